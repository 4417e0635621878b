"""Drives with a known torque lag for the diagnosis tests on a real server, and process helpers.

A diagnosis (or validation) cut off by ``kill -9`` of the server is resumed once by the one job
runner: tests/api/test_kill_each_kind.py; the attempt cap and a clean stop: tests/storage.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from app.ingest.database import load_database
from app.ingest.signalmap import load_signal_map
from sim.effects import apply_effects
from tests.conftest import REPO
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure_frames, run_truth
from tests.support.truthlog import write_blf

CANDIDATES = ["torque_lag", "speed_sensor", "drag"]


def write_lag_log(path: Path, seed: int = 41, duration_s: float = 30.0) -> Path:
    """``duration_s`` of tip-ins and tip-outs with a 15 ms torque lag, written as BLF through the reference DBC."""
    rng = np.random.default_rng(seed)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=duration_s))
    truth = run_truth(apply_effects(paper(), {"torque_lag": {"tau_s": 0.015, "delay_s": 0.0}}), drive)
    frames = measure_frames(drive, truth, CanSampling(offset_s=0.004, speed_res_rpm=0.0, torque_res_nm=0.0), rng)
    write_blf(path, frames, load_database(REPO / "dbc" / "lashscope_ev.dbc"),
              load_signal_map(REPO / "dbc" / "lashscope_ev.map.toml"))
    return path


def process_gone(pid: int, timeout: float = 10.0) -> bool:
    """Whether process ``pid`` has ended (or is a zombie nobody reaped yet) within ``timeout`` seconds."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
        except OSError:
            return True
        if stat.rsplit(")", 1)[-1].split()[0] == "Z":
            return True
        time.sleep(0.05)
    return False
