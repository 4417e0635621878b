"""``/batches``: the fleet batch pipeline over uploaded logs as one job, its rows over REST.

The app runs in the test process; the batch runs in the worker process the job runner spawns, on
three uploads: the demo drive, a drive with a known torque lag, and one whose stored file has gone
missing from the data directory (a failed row that must name the upload, not the stored file).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from tests.api.conftest import create_vehicle, upload
from tests.api.inprocess import TestClient, in_process
from tests.conftest import REPO
from tests.diagnosis.lagdrive import write_lag_log


@pytest.fixture(scope="module")
def lag_logs(tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    if not (REPO / "dbc" / "lashscope_ev.dbc").is_file():
        pytest.skip("the reference DBC and signal map are not in dbc/")
    root = tmp_path_factory.mktemp("batch")
    return [write_lag_log(root / f"lag{seed}.blf", seed) for seed in (61, 62)]


def _error(r: Any, status: int, code: str) -> None:
    assert r.status_code == status, r.text
    assert r.json()["code"] == code, r.json()


def _until_done(c: TestClient, url: str, timeout: float = 300.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    seen: set[str] = set()
    while time.monotonic() < deadline:
        doc: dict[str, Any] = c.get(url).json()
        seen.add(doc["status"])
        if doc["status"] in ("done", "failed"):
            doc["seen"] = sorted(seen)
            return doc
        time.sleep(0.3)
    raise AssertionError(f"{url} not finished in {timeout} s")


def test_a_batch_over_uploaded_logs(tmp_path: Path, demo_log: Path, lag_logs: list[Path]) -> None:
    with in_process(tmp_path / "data") as c:
        create_vehicle(c)
        demo, lag, lost = (upload(c, p).json() for p in (demo_log, *lag_logs))
        store = c.app.state.store  # type: ignore[attr-defined]
        store.get_log(lost["id"]).path.unlink()  # the disk lost it: that log fails, the batch goes on

        _error(c.post("/batches", json={"log_ids": [], "vehicle": "ev"}), 422, "validation_error")
        _error(c.post("/batches", json={"log_ids": ["log_nope"], "vehicle": "ev"}), 404, "not_found")
        _error(c.post("/batches", json={"log_ids": [demo["id"], demo["id"]], "vehicle": "ev"}), 400, "invalid_input")
        _error(c.post("/batches", json={"log_ids": [demo["id"]], "vehicle": "nope"}), 404, "not_found")
        _error(c.post("/batches", json={"log_ids": [demo["id"]], "vehicle": "ev", "options": {"model": "x"}}),
               400, "invalid_input")
        _error(c.get("/batches/ba_0000"), 404, "batch_not_found")
        assert store.job_counts()["queued"] == 0  # nothing was queued by the refused requests

        ids = [demo["id"], lag["id"], lost["id"]]
        r = c.post("/batches", json={"log_ids": ids, "vehicle": "ev", "vehicle_id": "ev-07"})
        assert r.status_code == 202, r.text
        batch = r.json()
        assert batch["status"] in ("queued", "running") and batch["logs"] == 3 and batch["vehicle_id"] == "ev-07"
        analysis = c.post("/analyses", json={"log_id": demo["id"], "vehicle": "ev"}).json()  # to compare with

        done = _until_done(c, f"/batches/{batch['id']}")
        assert done["status"] == "done", done
        assert done["counts"] == {"ok": 2, "failed": 1, "pending": 0}
        assert done["summary"]["logs"] == 3 and done["summary"]["ok"] == 2 and done["summary"]["skipped"] == 0
        assert done["job"]["attempts"] == 1 and done["progress"] == 1.0

        rows = c.get(f"/batches/{batch['id']}/logs").json()
        assert rows["count"] == 3 and [row["log_id"] for row in rows["logs"]] == ids
        ok, ok_lag, failed = rows["logs"]
        assert ok["status"] == "ok" and ok["filename"] == demo_log.name and ok["vehicle"] == "ev-07"
        assert ok_lag["status"] == "ok" and ok_lag["events"] > 0
        assert failed["status"] == "failed" and failed["code"] == "file_not_found"
        stored_name = store.get_log(lost["id"]).path.name
        assert lag_logs[1].name in failed["message"] and stored_name not in failed["message"]
        assert not any(str(tmp_path) in str(v) for row in rows["logs"] for v in row.values())  # no server paths

        # the batch's rows are the service's own analysis of the same log
        deadline = time.monotonic() + 120
        while c.get(f"/analyses/{analysis['id']}").json()["status"] != "done" and time.monotonic() < deadline:
            time.sleep(0.3)
        events = c.get(f"/analyses/{analysis['id']}/events").json()["events"]
        assert ok["events"] == len(events) >= 10
        assert ok["summary"]["events"] == c.get(f"/analyses/{analysis['id']}").json()["summary"]["events"]

        assert c.delete(f"/batches/{batch['id']}").status_code == 204
        _error(c.get(f"/batches/{batch['id']}"), 404, "batch_not_found")


def test_deleting_a_running_batch_cancels_its_job(tmp_path: Path, demo_log: Path) -> None:
    with in_process(tmp_path / "data") as c:
        create_vehicle(c)
        log_id = upload(c, demo_log).json()["id"]
        batch = c.post("/batches", json={"log_ids": [log_id], "vehicle": "ev", "diagnose": True}).json()
        assert c.delete(f"/batches/{batch['id']}").status_code == 204
        job = c.app.state.store.get_job(batch["job"]["id"])  # type: ignore[attr-defined]
        assert job.status.value == "failed" and job.error_code == "cancelled"
        assert c.get("/health").json()["jobs"]["running"] == 0
