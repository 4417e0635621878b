"""A diagnosis cut off by a server restart: resumed at the next start, or failed after too many attempts.

The end-to-end case runs the real server (``lashscope serve`` in a subprocess), kills it with
SIGKILL while a diagnosis is fitting, and starts it again on the same data directory. The attempt
cap and a clean stop are checked on the state machinery directly (no server needed).
"""

from __future__ import annotations

import json
import secrets
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

import httpx
import numpy as np
import pytest

from app.analysis.diagnosis.synthetic import CanSampling, DriveSpec, make_drive, measure_frames, run_truth
from app.analysis.diagnosis.truthlog import write_blf
from app.diagnosis_state import INTERRUPTED, MAX_ATTEMPTS, Stopping, Worker, recover, update
from app.ingest.database import load_database
from app.ingest.signalmap import load_signal_map
from sim.effects import apply_effects
from tests.api.conftest import Server, create_vehicle, upload, wait_for
from tests.conftest import REPO
from tests.diagnosis.conftest import paper

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


@pytest.fixture(scope="module")
def lag_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_lag_log(tmp_path_factory.mktemp("restart") / "lag.blf")


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


def _poll(c: httpx.Client, did: str, until: Any, timeout: float = 120.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        doc: dict[str, Any] = c.get(f"/diagnoses/{did}").json()
        if until(doc):
            return doc
        time.sleep(0.05)
    raise AssertionError(f"diagnosis {did} did not get there in {timeout} s: {doc}")


def test_a_diagnosis_killed_with_the_server_resumes_at_the_next_start(tmp_path: Path, lag_log: Path) -> None:
    data = tmp_path / "data"
    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            create_vehicle(c)
            log_id = upload(c, lag_log).json()["id"]
            analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            assert wait_for(c, analysis_id)["status"] == "done"
            r = c.post(f"/analyses/{analysis_id}/diagnoses", json={"candidates": CANDIDATES, "seed": 2})
            assert r.status_code == 202, r.text
            did = r.json()["id"]
            running = _poll(c, did, lambda d: d["status"] == "running" and d["stage"] != "decoding")
            assert running["attempts"] == 1
    finally:
        pid = srv.proc.pid if srv.proc else -1
        srv.stop(signal.SIGKILL)  # no shutdown at all: the state file says "running" for a dead owner
    st_path = data / "analyses" / analysis_id / "diagnoses" / did / "status.json"
    left = json.loads(st_path.read_text(encoding="utf-8"))
    assert left["status"] == "running" and left["owner"]["pid"] == pid
    # the fit ran in a worker process, and that died with the server rather than fitting on as an orphan
    assert left["worker_pid"] != pid
    assert process_gone(left["worker_pid"])

    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            doc = _poll(c, did, lambda d: d["status"] in ("done", "failed"))
            assert doc["status"] == "done", doc
            assert doc["attempts"] == 2
            assert doc["report"]["decision"]["top"] == ["torque_lag"]
            assert doc["report"]["split"]["seed"] == 2
    finally:
        srv.stop()


def _dead_owner() -> dict[str, Any]:
    pid = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                             text=True).stdout)
    return {"pid": pid, "started": None, "token": secrets.token_hex(4)}


def test_work_cut_off_too_often_is_failed_with_the_reason(tmp_path: Path) -> None:
    path = tmp_path / "status.json"
    update(path, status="running", attempts=MAX_ATTEMPTS, owner=_dead_owner())
    ran: list[int] = []
    worker = Worker(in_process=True)
    try:
        done = recover([("d1", path, lambda: lambda check: ran.append(1))], worker)
    finally:
        worker.close()
    assert done == {"resumed": [], "failed": ["d1"]}
    doc = json.loads(path.read_text(encoding="utf-8"))
    assert doc["status"] == "failed" and INTERRUPTED in doc["error"]["detail"] and not ran


def test_queued_work_and_a_clean_stop_resume_without_counting_an_attempt(tmp_path: Path) -> None:
    path = tmp_path / "status.json"
    update(path, status="queued", attempts=1, owner=_dead_owner())
    finished = threading.Event()

    def finish(check: Any) -> None:
        update(path, status="done")
        finished.set()

    worker = Worker(in_process=True)
    try:
        done = recover([("d1", path, lambda: finish)], worker)
        assert done["resumed"] == ["d1"] and finished.wait(10)
        assert json.loads(path.read_text(encoding="utf-8"))["attempts"] == 1
        # resumed once per dead owner: a second recovery (another process on the same directory) leaves it
        update(path, status="queued", owner=_dead_owner())
        assert recover([("d1", path, lambda: lambda check: None)], worker)["resumed"] == ["d1"]
        assert recover([("d1", path, lambda: lambda check: None)], worker)["resumed"] == []
    finally:
        worker.close()

    # a stop while running puts the work back in the queue, with its attempts unchanged
    stopped = tmp_path / "stopped.json"
    update(stopped, status="queued", attempts=1)
    worker = Worker(in_process=True)
    started = threading.Event()

    def work(check: Any) -> None:
        update(stopped, status="running")
        started.set()
        while True:
            check()
            time.sleep(0.01)

    worker.submit(stopped, work)
    assert started.wait(10)
    worker.close()
    deadline = time.monotonic() + 10
    while json.loads(stopped.read_text(encoding="utf-8"))["status"] != "queued" and time.monotonic() < deadline:
        time.sleep(0.02)
    doc = json.loads(stopped.read_text(encoding="utf-8"))
    assert doc["status"] == "queued" and doc["attempts"] == 1
    with pytest.raises(Stopping):
        worker.check()
