"""Shared fixtures: paths to the public sample data beside the repo (``../shared``)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("LASHSCOPE_SHARED", REPO.parent / "shared")).resolve()
DATA = SHARED / "data"


def shared_file(*parts: str) -> Path:
    """A file under ``../shared/data``; skips the test with a reason when it is absent."""
    path = DATA.joinpath(*parts)
    if not path.exists():
        pytest.skip(f"public sample data not found: {path} (set LASHSCOPE_SHARED)")
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not DATA.is_dir():
        pytest.skip(f"public sample data folder not found: {DATA} (set LASHSCOPE_SHARED)")
    return DATA


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Tests that start ``lashscope serve`` in a subprocess are ``slow``: ``pytest -m "not slow"`` is the
    development lane (the same code paths run in-process in ``tests/api/test_limits.py`` and
    ``test_security.py``); CI runs everything."""
    from tests.api.conftest import Server

    for item in items:
        module = getattr(item, "module", None)
        if getattr(module, "Server", None) is Server or {"server", "small_cap_server"} & set(
                getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.slow)
