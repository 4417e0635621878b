"""Job leases between processes: two runners on one store never hold the same job (both backends).

Each test starts two real Python processes on the same store (the ``store_url`` fixture: a SQLite
file, or a database on the test PostgreSQL server), lets both get ready, releases them at once and
compares what each one says it took with what the database says.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

from app.storage.records import JobStatus
from app.storage.sqlstore import SQLStore
from app.storage.url import open_store
from tests.conftest import REPO

if TYPE_CHECKING:
    from tests.pgserver import PgServer

JOBS = 120

# mode "start": try to start every queued job (all in the same order, so the two collide on each one).
# mode "recover": three recovery passes, starting each job a pass hands back.
_TAKER = """
import json, sys
from app.storage.url import open_store
url, me, mode = sys.argv[1:4]
store = open_store(url)
queued = [j.id for j in store.pending_jobs()]
print("ready", flush=True)
sys.stdin.readline()
won = []
if mode == "start":
    for job_id in queued:
        job = store.start_job(job_id, me, 60.0)
        if job.status.value == "running" and job.lease_owner == me:
            won.append(job_id)
else:
    for _ in range(3):
        for job in store.requeue_orphans(5):
            got = store.start_job(job.id, me, 60.0)
            if got.status.value == "running" and got.lease_owner == me:
                won.append(job.id)
store.close()
print(json.dumps(won), flush=True)
"""


def _race(url: str, mode: str) -> dict[str, list[str]]:
    """Run two takers against ``url`` released at the same moment; what each one took."""
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    procs = {me: subprocess.Popen([sys.executable, "-c", _TAKER, url, me, mode], cwd=REPO, env=env, text=True,
                                  stdin=subprocess.PIPE, stdout=subprocess.PIPE)
             for me in ("runner-a", "runner-b")}
    try:
        for p in procs.values():
            assert p.stdout is not None and p.stdout.readline().strip() == "ready"
        for p in procs.values():  # release both
            assert p.stdin is not None
            p.stdin.write("go\n")
            p.stdin.flush()
        out = {me: p.communicate(timeout=180)[0] for me, p in procs.items()}
    finally:
        for p in procs.values():
            if p.poll() is None:
                p.kill()
                p.wait()
    assert all(p.returncode == 0 for p in procs.values()), out
    return {me: json.loads(text.strip().splitlines()[-1]) for me, text in out.items()}


def _assert_disjoint_and_complete(store: SQLStore, won: dict[str, list[str]], ids: list[str],
                                  attempts: int) -> None:
    a, b = set(won["runner-a"]), set(won["runner-b"])
    assert len(a) == len(won["runner-a"]) and len(b) == len(won["runner-b"])  # nobody took one twice
    assert not a & b
    assert a | b == set(ids)
    for job_id in ids:
        job = store.get_job(job_id)
        owner = "runner-a" if job_id in a else "runner-b"
        assert (job.status, job.lease_owner, job.attempts) == (JobStatus.RUNNING, owner, attempts)
        assert job.lease_until is not None and job.lease_until > time.time() + 30


def test_two_processes_starting_the_same_queued_jobs_never_both_get_one(store: SQLStore, store_url: str) -> None:
    ids = [store.create_job("analysis", f"an_{i}").id for i in range(JOBS)]
    won = _race(store_url, "start")
    _assert_disjoint_and_complete(store, won, ids, attempts=1)


def test_two_recovery_passes_never_both_take_back_a_job(store: SQLStore, store_url: str) -> None:
    ids = [store.create_job("analysis", f"an_{i}").id for i in range(JOBS)]
    for job_id in ids:  # started by a runner that died: its lease ran out a second ago
        assert store.start_job(job_id, "gone", -1.0).lease_owner == "gone"
    won = _race(store_url, "recover")
    # each job was taken back once and started once more: a second take-back would show attempts == 3
    _assert_disjoint_and_complete(store, won, ids, attempts=2)


def test_a_recovery_pass_skips_a_job_another_transaction_is_changing(pg_server: PgServer, tmp_path: Path) -> None:
    """PostgreSQL: rows locked elsewhere (a runner renewing its lease) are skipped, not waited for or taken."""
    import psycopg

    url = pg_server.database()
    store = open_store(f"{url}?files={tmp_path}")
    ids = [store.create_job("analysis", f"an_{i}").id for i in range(3)]
    for job_id in ids:
        store.start_job(job_id, "gone", -1.0)
    with psycopg.connect(url) as other:  # holds a row lock on the first job until this block ends
        other.execute("SELECT id FROM jobs WHERE id = %s FOR UPDATE", (ids[0],))
        result: list[list[str]] = []
        recovery = threading.Thread(target=lambda: result.append([j.id for j in store.requeue_orphans(5)]))
        recovery.start()
        recovery.join(60)
        assert not recovery.is_alive(), "the recovery pass waited for a row another transaction holds"
        assert sorted(result[0]) == sorted(ids[1:])
    assert store.get_job(ids[0]).status is JobStatus.RUNNING
    assert [j.id for j in store.requeue_orphans(5)] == [ids[0]]  # once the lock is gone, it is taken back
    store.close()


def test_lease_times_keep_their_precision(store: SQLStore) -> None:
    """Epoch seconds in a 4-byte float would be off by minutes; the store keeps a double on both backends."""
    job = store.create_job("analysis", "an_x")
    before = time.time()
    started = store.start_job(job.id, "me", 10.0)
    assert started.lease_until is not None and before + 10.0 <= started.lease_until <= time.time() + 10.0
    assert store.get_job(job.id).lease_until == started.lease_until
    assert store.renew_lease(job.id, "me", 20.0) and not store.renew_lease(job.id, "other", 20.0)
    renewed = store.get_job(job.id).lease_until
    assert renewed is not None and abs(renewed - (time.time() + 20.0)) < 5.0


def test_stale_upload_files_are_cleaned_and_fresh_ones_kept(store: SQLStore, tmp_path: Path) -> None:
    old, fresh = store.temp_path(".blf"), store.temp_path(".blf")
    old.write_bytes(b"cut off")
    fresh.write_bytes(b"arriving")
    os.utime(old, (time.time() - 600, time.time() - 600))
    assert store.clean_temp(older_than_s=120) == 1
    assert not old.exists() and fresh.exists()
    assert store.clean_temp() == 1 and list((tmp_path / "tmp").iterdir()) == []
