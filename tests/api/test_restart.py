"""Stop the server, start it again on the same data directory: everything is still there.

(A job cut off more often than the attempts allow is marked failed: tests/storage.)
"""

from __future__ import annotations

import signal
import sqlite3
import subprocess
import sys
from pathlib import Path

import httpx

from tests.api.conftest import Server, analysed, wait_for


def test_data_survives_a_restart_and_a_killed_server(tmp_path: Path, demo_log: Path) -> None:
    data = tmp_path / "data"
    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            log_id, analysis_id = analysed(c, demo_log)
            before = c.get(f"/analyses/{analysis_id}/metrics").json()
    finally:
        srv.stop(signal.SIGKILL)  # no graceful shutdown: SQLite (WAL) must still have everything
    assert not srv.alive

    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            assert [x["id"] for x in c.get("/logs").json()] == [log_id]
            assert c.get("/vehicles/ev").json()["version"] == 1
            assert c.get(f"/analyses/{analysis_id}").json()["status"] == "done"
            assert c.get(f"/analyses/{analysis_id}/metrics").json() == before
            # a second analysis, queued, then the server is "cut off" while it runs
            second = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            wait_for(c, second)
    finally:
        srv.stop()

    # mark the second job as running in a process that has died: what a crash mid-job leaves behind
    dead = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True).stdout)
    with sqlite3.connect(data / "lashscope.sqlite3") as db:
        job_id = db.execute("SELECT job_id FROM analyses WHERE id = ?", (second,)).fetchone()[0]
        db.execute("UPDATE jobs SET status = 'running', stage = 'simulate', progress = 0.5, owner_pid = ?,"
                   " attempts = 1 WHERE id = ?", (dead, job_id))
    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            resumed = wait_for(c, second)
            assert resumed["status"] == "done" and resumed["job"]["attempts"] == 2
    finally:
        srv.stop()
