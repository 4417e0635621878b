"""Jobs on a real server: kill -9 mid-job (the worker dies with it, the job runs again exactly once
after its lease lapses), and deleting an analysis cancels its running jobs and forgets its answers."""

from __future__ import annotations

import signal
from pathlib import Path

import httpx
import pytest

from tests.api.conftest import Server, analysed, assert_gone, create_vehicle, running_worker, upload, wait_for

pytestmark = pytest.mark.slow


def test_kill_9_mid_analysis_runs_it_once_more(tmp_path: Path, demo_log: Path,
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LASHSCOPE_JOB_LEASE_S", "2")
    data = tmp_path / "data"
    srv = Server(data).start()
    with httpx.Client(base_url=srv.url, timeout=60.0) as c:
        create_vehicle(c)
        log_id = upload(c, demo_log).json()["id"]
        analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
        workers = running_worker(c, srv, f"/analyses/{analysis_id}")
    srv.stop(signal.SIGKILL)
    assert_gone(workers, "a worker outlived its killed server")

    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            body = wait_for(c, analysis_id, timeout=180.0)
            assert body["status"] == "done", body
            assert body["job"]["attempts"] == 2  # the cut-off run and one more, never two at once
            assert c.get(f"/analyses/{analysis_id}/metrics").json()["events"]
    finally:
        srv.stop()


def test_delete_cancels_running_jobs_and_forgets_cached_series(tmp_path: Path, demo_log: Path) -> None:
    srv = Server(tmp_path / "data").start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            log_id, analysis_id = analysed(c, demo_log)
            speed = c.get(f"/analyses/{analysis_id}/speed", params={"max_points": 500})
            assert speed.status_code == 200 and speed.json()["points"] > 0  # now cached in memory

            tol = f"/analyses/{analysis_id}/tolerance"
            for _ in range(5):  # reading never starts work
                r = c.get(tol, params={"n": 2000, "seed": 1})
                assert r.status_code == 404 and r.json()["code"] == "tolerance_not_started"
            assert c.get("/health").json()["jobs"]["queued"] == 0
            started = c.post(tol, params={"n": 2000, "seed": 1})
            assert started.status_code == 202
            assert c.post(tol, params={"n": 2000, "seed": 1}).json()["job_id"] == started.json()["job_id"]
            workers = running_worker(c, srv, f"{tol}?n=2000&seed=1")

            assert c.delete(f"/analyses/{analysis_id}").status_code == 204
            assert_gone(workers, "the deleted analysis' tolerance worker still runs")
            gone = c.get(f"/analyses/{analysis_id}/speed", params={"max_points": 500})
            assert gone.status_code == 404 and gone.json()["code"] == "not_found"
            assert c.get(f"/analyses/{analysis_id}").status_code == 404
            jobs = c.get("/health").json()["jobs"]
            assert jobs["running"] == 0 and jobs["queued"] == 0 and jobs["failed"] == 1  # the cancelled band
            assert c.delete(f"/logs/{log_id}").status_code == 204
    finally:
        srv.stop()
