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

__all__ = ["TestClient", "in_process", "stored_analysis"]


@contextmanager
def in_process(data_dir: Path, **settings: Any) -> Iterator[TestClient]:
    """A client of a fresh app on ``data_dir``; the test client's ``Host: testserver`` is allowed."""
    cfg = Settings(data_dir=data_dir, allowed_hosts=["testserver", *settings.pop("allowed_hosts", [])], **settings)
    with TestClient(create_app(cfg)) as client:
        yield client


def stored_analysis(client: TestClient, sha256: str, filename: str) -> tuple[Any, Any]:
    """Vehicle ``ev`` (the paper preset) and an analysis of a one-frame candump log stored under ``sha256``, its job
    not started: ``(store, analysis)``, for tests that need stored records without running an analysis."""
    store = client.app.state.store  # type: ignore[attr-defined]
    assert client.post("/vehicles", data={"name": "ev", "preset": "paper"}).status_code == 201
    log = store.temp_path(".log")
    log.write_bytes(b"(0.000000) can0 123#00\n")
    rec, _ = store.add_log(log, sha256=sha256, filename=filename, fmt="candump", frames=1, duration_s=0.0,
                           start_time=None, issues=[], meta={})
    return store, store.create_analysis(rec.id, store.get_vehicle("ev"), {})
