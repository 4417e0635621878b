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
