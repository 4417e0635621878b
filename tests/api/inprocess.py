"""The API in this process (Starlette's TestClient): for tests of the request guard and limits,
which need no worker processes and would otherwise pay a server start-up each."""

from __future__ import annotations

import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*httpx.*")
    from fastapi.testclient import TestClient

from app.api.main import create_app
from app.settings import Settings

__all__ = ["TestClient", "in_process"]


@contextmanager
def in_process(data_dir: Path, **settings: Any) -> Iterator[TestClient]:
    """A client of a fresh app on ``data_dir``; the test client's ``Host: testserver`` is allowed."""
    cfg = Settings(data_dir=data_dir, allowed_hosts=["testserver", *settings.pop("allowed_hosts", [])], **settings)
    with TestClient(create_app(cfg)) as client:
        yield client
