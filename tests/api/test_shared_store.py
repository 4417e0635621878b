"""Two API servers on one PostgreSQL store: what one stores the other serves, and when one is killed
mid-analysis the other takes the job over once the lease has run out and runs it exactly once more."""

from __future__ import annotations

import signal
from pathlib import Path
from typing import TYPE_CHECKING

import httpx
import pytest

from tests.api.conftest import Server, assert_gone, create_vehicle, running_worker, upload, wait_for

if TYPE_CHECKING:
    from tests.pgserver import PgServer

pytestmark = pytest.mark.slow


def test_two_servers_share_one_postgresql_store(tmp_path: Path, demo_log: Path, pg_server: PgServer,
                                                monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LASHSCOPE_JOB_LEASE_S", "2")
    store = ("--store", f"{pg_server.database()}?files={tmp_path / 'files'}")
    a = Server(tmp_path / "a", extra_args=store).start()
    b = Server(tmp_path / "b", extra_args=store).start()
    try:
        with httpx.Client(base_url=a.url, timeout=60.0) as ca, httpx.Client(base_url=b.url, timeout=60.0) as cb:
            assert create_vehicle(ca)["version"] == 1
            log_id = upload(cb, demo_log).json()["id"]
            assert [x["id"] for x in ca.get("/logs").json()] == [log_id]
            assert cb.get("/vehicles/ev").json()["version"] == 1
            assert upload(ca, demo_log).json()["id"] == log_id  # the same bytes, stored once

            first = cb.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            done = wait_for(ca, first)
            assert done["status"] == "done" and done["job"]["attempts"] == 1, done
            metrics = ca.get(f"/analyses/{first}/metrics").json()
            assert metrics["events"] and cb.get(f"/analyses/{first}/metrics").json() == metrics

            second = cb.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            workers = running_worker(cb, b, f"/analyses/{second}")
            b.stop(signal.SIGKILL)
            assert_gone(workers, "a worker outlived its killed server")

            taken_over = wait_for(ca, second, timeout=240.0)  # A's recovery pass resumes it
            assert taken_over["status"] == "done" and taken_over["job"]["attempts"] == 2, taken_over
            again = ca.get(f"/analyses/{second}/metrics").json()
            assert again.pop("analysis_id") == second and metrics.pop("analysis_id") == first
            assert again == metrics  # same log, vehicle and options: the same answers
            health = ca.get("/health").json()
            assert health["database"] == "ok" and health["jobs"] == {"queued": 0, "running": 0, "done": 2,
                                                                     "failed": 0}
    finally:
        b.stop()
        a.stop()
