"""Tiny demo logs (12 s, fixed seeds) shared by the fleet tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.settings import default_dbc_dir

DBC = default_dbc_dir() / "lashscope_ev.dbc"
MAP = default_dbc_dir() / "lashscope_ev.map.toml"


@pytest.fixture(scope="package")
def fleet_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """car-a/log0.blf, car-a/log1.blf, car-b/log2.blf and an unreadable car-b/broken.blf."""
    root = tmp_path_factory.mktemp("fleet")
    logs = {}
    for k, car in enumerate(("car-a", "car-a", "car-b")):
        path = root / car / f"log{k}.blf"
        build_demo_log(path, DBC, MAP, Scenario(duration_s=12.0, seed=100 + k))
        logs[f"log{k}"] = path
    broken = root / "car-b" / "broken.blf"
    broken.write_bytes(b"LOGG" + bytes(range(256)) * 4)  # a BLF signature, then garbage
    logs["broken"] = broken
    return logs
