"""A diagnosis runs in its own worker process: over LASHSCOPE_DIAGNOSIS_TIMEOUT_S it is killed and fails with
code ``timeout`` while ``/health`` keeps answering; a SIGTERM of the server stops the worker and puts the
diagnosis back to be resumed at the next start without counting an attempt. Both against the real server
(``lashscope serve`` on 127.0.0.1)."""

from __future__ import annotations

import signal
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.api.conftest import Server, create_vehicle, upload, wait_for, worker_pids
from tests.api.test_kill_each_kind import _job
from tests.diagnosis.lagdrive import CANDIDATES, process_gone, write_lag_log


@pytest.fixture(scope="module")
def lag_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    # twice the usual drive, so the whole-library fit runs well past the time limit below
    return write_lag_log(tmp_path_factory.mktemp("isolation") / "lag.blf", seed=43, duration_s=60.0)


def _start_diagnosis(c: httpx.Client, log: Path, body: dict[str, Any]) -> tuple[str, str]:
    """Upload ``log``, analyse it and start a diagnosis of the analysis with request ``body``."""
    create_vehicle(c)
    log_id = upload(c, log).json()["id"]
    analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
    assert wait_for(c, analysis_id)["status"] == "done"  # so the diagnosis has both cores to itself
    r = c.post(f"/analyses/{analysis_id}/diagnoses", json=body)
    assert r.status_code == 202, r.text
    return analysis_id, r.json()["id"]


def test_a_diagnosis_over_its_time_limit_fails_while_health_answers(tmp_path: Path, lag_log: Path,
                                                                    monkeypatch: pytest.MonkeyPatch) -> None:
    # far too short to diagnose this log (the identification and the library take several seconds of CPU; the
    # worker's imports alone ~1.5 s on a quiet machine): the limit ends it whatever it is doing by then
    monkeypatch.setenv("LASHSCOPE_DIAGNOSIS_TIMEOUT_S", "3")
    data = tmp_path / "data"
    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            _, did = _start_diagnosis(c, lag_log, {"seed": 1})  # the whole effect library
            deadline = time.monotonic() + 90.0
            health_checks, seen, workers = 0, set(), set()
            assert srv.proc is not None
            while True:
                workers.update(worker_pids(srv.proc.pid))
                # a server whose GIL a fit held would raise a timeout here
                assert c.get("/health", timeout=5.0).status_code == 200
                health_checks += 1
                doc = c.get(f"/diagnoses/{did}").json()
                seen.add(doc["status"])
                if doc["status"] in ("done", "failed") or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            assert doc["status"] == "failed", {k: doc[k] for k in ("status", "stage", "progress")}
            assert doc["error"]["code"] == "timeout"
            assert "timed out after 3 s" in doc["error"]["detail"]
            # whether the worker reported "running" before the limit depends on the machine's load (its imports
            # alone took ~10 s at load average 10); progress reaching the job row is test_kill_each_kind's to check
            assert "LASHSCOPE_DIAGNOSIS_TIMEOUT_S" in doc["error"]["detail"]
            assert health_checks >= 5
            assert doc.get("report") is None  # the response model keeps the key, empty until done
            assert c.get("/health", timeout=5.0).json()["status"] == "ok"
            assert all(process_gone(pid, timeout=1.0) for pid in workers)
    finally:
        srv.stop()


def test_sigterm_stops_the_worker_and_requeues_the_diagnosis(tmp_path: Path, lag_log: Path) -> None:
    data = tmp_path / "data"
    srv = Server(data).start()
    proc = srv.proc
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            _, did = _start_diagnosis(c, lag_log, {"candidates": CANDIDATES, "seed": 1})
            deadline = time.monotonic() + 90.0
            while time.monotonic() < deadline:
                doc = c.get(f"/diagnoses/{did}").json()
                if doc["status"] != "queued":
                    break
                time.sleep(0.05)
            assert doc["status"] == "running", doc
            assert proc is not None
            workers = worker_pids(proc.pid)
            while not workers and time.monotonic() < deadline:
                time.sleep(0.05)
                workers = worker_pids(proc.pid)
            assert workers
    finally:
        srv.stop(signal.SIGTERM)
    assert proc is not None and proc.returncode is not None  # uvicorn re-raises SIGTERM after its clean shutdown
    left = _job(data, doc["job_id"])
    assert left["status"] == "running" and left["lease_until"] == 0 and left["attempts"] == 0, left
    assert "stopped with the server" in left["stage"]
    assert all(process_gone(pid, timeout=1.0) for pid in workers)

    srv = Server(data).start()  # the next start resumes it at once and runs it to the end
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            deadline = time.monotonic() + 180.0
            while time.monotonic() < deadline:
                doc = c.get(f"/diagnoses/{did}").json()
                if doc["status"] in ("done", "failed"):
                    break
                time.sleep(0.2)
            assert doc["status"] == "done" and doc["attempts"] == 1, doc
            assert doc["report"]["decision"]["top"] == ["torque_lag"]
    finally:
        srv.stop()
