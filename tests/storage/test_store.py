"""The store on both backends (SQLite, PostgreSQL): de-duplication, versions, jobs across restarts,
concurrent writers. The ``store`` fixture (tests/conftest.py) opens each test on both, files in ``tmp_path``."""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from app.errors import ConflictError, InputError, NotFoundError
from app.storage import JobStatus
from app.storage.results import ResultFiles, json_safe, write_result
from app.storage.sqlstore import SQLStore
from app.storage.url import open_store


def _add_log(store: SQLStore, content: bytes, name: str = "a.blf") -> tuple[str, bool]:
    tmp = store.temp_path(".blf")
    tmp.write_bytes(content)
    rec, created = store.add_log(tmp, sha256=hashlib.sha256(content).hexdigest(), filename=name, fmt="blf",
                                 frames=10, duration_s=1.0, start_time=None, issues=[], meta={})
    assert not tmp.exists()
    return rec.id, created


def _vehicle_files(tmp_path: Path, tag: str) -> dict[str, Path]:
    files = {}
    for key in ("driveline", "database", "signal_map"):
        p = tmp_path / f"{key}-{tag}.txt"
        p.write_text(f"{key} {tag}")
        files[key] = p
    return files


def test_logs_are_deduplicated_by_content(store: SQLStore, tmp_path: Path) -> None:
    a, created_a = _add_log(store, b"one")
    b, created_b = _add_log(store, b"one", "renamed.blf")
    c, _ = _add_log(store, b"two")
    assert created_a and not created_b and a == b and a != c
    assert len(list((tmp_path / "logs").iterdir())) == 2
    store.delete_log(a)
    with pytest.raises(NotFoundError):
        store.get_log(a)
    assert len(list((tmp_path / "logs").iterdir())) == 1


def test_vehicle_versions_and_unchanged_content(store: SQLStore, tmp_path: Path) -> None:
    v1, new1 = store.add_vehicle("ev-1", **_vehicle_files(tmp_path, "a"), summary={"k": 1})
    same, new_same = store.add_vehicle("ev-1", **_vehicle_files(tmp_path, "a"), summary={})
    v2, new2 = store.add_vehicle("ev-1", **_vehicle_files(tmp_path, "b"), summary={})
    assert (v1.version, new1, same.version, new_same, v2.version, new2) == (1, True, 1, False, 2, True)
    assert store.get_vehicle("ev-1").version == 2
    assert store.get_vehicle("ev-1", 1).driveline_path.read_text() == "driveline a"
    assert [v.version for v in store.vehicle_versions("ev-1")] == [1, 2]
    with pytest.raises(InputError, match="vehicle name"):
        store.add_vehicle("Bad Name!", **_vehicle_files(tmp_path, "c"), summary={})


def test_everything_survives_a_reopen_and_interrupted_jobs_are_resumed_then_failed(store: SQLStore,
                                                                                   tmp_path: Path) -> None:
    log_id, _ = _add_log(store, b"log")
    veh, _ = store.add_vehicle("car", **_vehicle_files(tmp_path, "x"), summary={})
    rec = store.create_analysis(log_id, veh, {"model": "multibody"})
    store.start_job(rec.job.id)
    store.close()

    # simulate a crash: the job row says running, owned by a process that no longer exists
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    reopened = open_store(store.url)
    reopened._conn().execute("UPDATE jobs SET owner_pid = ?", (int(dead.stdout),))
    assert reopened.get_log(log_id).filename == "a.blf"
    assert reopened.get_vehicle("car").version == 1
    pending = reopened.recover_jobs(max_attempts=2)
    assert [j.id for j in pending] == [rec.job.id]
    assert "resumed" in reopened.get_job(rec.job.id).stage

    reopened.start_job(rec.job.id)  # second attempt, cut off again
    reopened._conn().execute("UPDATE jobs SET owner_pid = ?", (int(dead.stdout),))
    assert reopened.recover_jobs(max_attempts=2) == []
    job = reopened.get_job(rec.job.id)
    assert job.status is JobStatus.FAILED and job.error_code == "interrupted"
    assert "2 of 2 attempts" in (job.error_detail or "")
    reopened.close()


def test_a_job_owned_by_a_live_process_is_left_alone(store: SQLStore) -> None:
    job = store.create_job("analysis", "x")
    store.start_job(job.id)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        store._conn().execute("UPDATE jobs SET owner_pid = ?", (other.pid,))
        assert store.recover_jobs(2) == []
        assert store.get_job(job.id).status is JobStatus.RUNNING
    finally:
        other.kill()
        other.wait()


def test_busy_analysis_blocks_log_delete(store: SQLStore, tmp_path: Path) -> None:
    log_id, _ = _add_log(store, b"log")
    veh, _ = store.add_vehicle("car", **_vehicle_files(tmp_path, "x"), summary={})
    rec = store.create_analysis(log_id, veh, {})
    with pytest.raises(ConflictError):
        store.delete_log(log_id)
    with pytest.raises(ConflictError):
        store.delete_analysis(rec.id)
    store.fail_job(rec.job.id, "x", "y")
    store.delete_log(log_id)
    with pytest.raises(NotFoundError):
        store.get_analysis(rec.id)


def test_active_jobs_of_an_analysis_include_its_tolerance_bands(store: SQLStore, tmp_path: Path) -> None:
    log_id, _ = _add_log(store, b"log")
    veh, _ = store.add_vehicle("car", **_vehicle_files(tmp_path, "x"), summary={})
    rec = store.create_analysis(log_id, veh, {})
    band = store.create_job("tolerance", f"{rec.id}/n=200/seed=1")
    other = store.create_job("tolerance", f"{rec.id}x/n=200/seed=1")  # another id with this one as prefix
    assert {j.id for j in store.active_jobs(rec.id)} == {rec.job.id, band.id}
    store.finish_job(band.id)
    assert [j.id for j in store.active_jobs(rec.id)] == [rec.job.id]
    assert store.find_job("tolerance", f"{rec.id}x/n=200/seed=1") == store.get_job(other.id)
    assert store.job_counts() == {"queued": 2, "running": 0, "done": 1, "failed": 0}


def test_concurrent_writers_from_threads_and_processes(store: SQLStore) -> None:
    errors: list[BaseException] = []

    def worker(k: int) -> None:
        try:
            for i in range(15):
                _add_log(store, f"{k}-{i}".encode())
                _add_log(store, b"shared")  # every thread also uploads the same bytes
        except BaseException as exc:
            errors.append(exc)

    code = ("import hashlib,sys; from app.storage.url import open_store; s=open_store(sys.argv[1])\n"
            "for i in range(15):\n"
            "    b=f'p-{i}'.encode(); t=s.temp_path(); t.write_bytes(b)\n"
            "    s.add_log(t, sha256=hashlib.sha256(b).hexdigest(), filename='p', fmt='blf', frames=1,"
            " duration_s=0.0, start_time=None, issues=[], meta={})\n")
    proc = subprocess.Popen([sys.executable, "-c", code, store.url], cwd=Path(__file__).resolve().parents[2],
                            env={**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])})
    threads = [threading.Thread(target=worker, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert proc.wait(60) == 0
    assert not errors
    assert len(store.list_logs(limit=1000)) == 4 * 15 + 1 + 15


def test_result_files_round_trip_and_nan_to_null(tmp_path: Path) -> None:
    d = tmp_path / "res"
    write_result(d, {"x": float("nan"), "y": [1.0, float("inf")]}, {"a": np.arange(5.0)})
    files = ResultFiles(d)
    assert files.doc == {"x": None, "y": [1.0, None]}
    np.testing.assert_array_equal(files.array("a"), np.arange(5.0))
    assert json_safe({"k": np.float64(2.5)}) == {"k": 2.5}
    with pytest.raises(NotFoundError):
        files.array("missing")


def test_writing_a_result_keeps_what_else_lives_in_the_directory(tmp_path: Path) -> None:
    """A diagnosis started before its analysis finished writes into the same directory: storing the
    analysis' result (twice: a resumed job writes it again) must not wipe it."""
    d = tmp_path / "an_1"
    status = d / "diagnoses" / "an_1--dg01" / "status.json"
    status.parent.mkdir(parents=True)
    status.write_text('{"id": "an_1--dg01"}', encoding="utf-8")
    (d / "tolerance_n10_seed0.json").write_text("{}", encoding="utf-8")
    write_result(d, {"run": 1}, {"a": np.arange(3.0), "b": np.ones(2)})
    write_result(d, {"run": 2}, {"a": np.arange(4.0)})
    assert status.read_text(encoding="utf-8") == '{"id": "an_1--dg01"}'
    assert (d / "tolerance_n10_seed0.json").is_file()
    files = ResultFiles(d)
    assert files.doc == {"run": 2}
    np.testing.assert_array_equal(files.array("a"), np.arange(4.0))
    assert not files.has("b")  # the second result replaced the first one's arrays whole
    assert sorted(p.name for p in d.iterdir()) == ["arrays", "diagnoses", "result.json", "tolerance_n10_seed0.json"]


def test_a_clean_stop_resumes_the_job_at_once_without_counting_an_attempt(store: SQLStore) -> None:
    """The server stopping (SIGTERM) lets the lease go: any runner resumes the job at once, and the
    attempt it cut off is not counted -- only crashes use up LASHSCOPE_JOB_MAX_ATTEMPTS."""
    job = store.create_job("diagnosis", "an_1/diagnoses/an_1--dg01")
    store.start_job(job.id, "server-a", lease_s=600.0)
    assert store.requeue_orphans(2) == []  # the lease still runs: nobody else may take it
    store.release_lease(job.id, "someone-else")  # only the lease's owner can let it go
    assert store.get_job(job.id).attempts == 1 and store.requeue_orphans(2) == []
    store.release_lease(job.id, "server-a")
    stopped = store.get_job(job.id)
    assert stopped.status is JobStatus.RUNNING and stopped.attempts == 0 and "stopped with the server" in stopped.stage
    for _ in range(3):  # stopped cleanly again and again: never failed for it
        [again] = store.requeue_orphans(max_attempts=2)
        assert again.id == job.id and again.stage == "resumed after a clean stop"
        assert store.start_job(job.id, "server-b", lease_s=600.0).attempts == 1
        store.release_lease(job.id, "server-b")
    assert store.get_job(job.id).status is JobStatus.RUNNING


def test_ids_and_messages_with_a_nul_byte(store: SQLStore) -> None:
    """A client's id with a NUL is not found on either backend (PostgreSQL text cannot hold one: no driver error
    may reach the client as a 500), and a job's error message with one is kept."""
    for lookup in (store.get_log, store.get_analysis, store.get_vehicle):
        with pytest.raises(NotFoundError):
            lookup("x\x00y")
    assert store.find_job("identification", "id_\x00") is None
    job = store.create_job("analysis", "an_nul")
    store.fail_job(job.id, "log_format", "line 3: 'a\x00b' is not a frame")
    detail = store.get_job(job.id).error_detail
    assert detail in ("line 3: 'a\x00b' is not a frame", "line 3: 'a\ufffdb' is not a frame")
