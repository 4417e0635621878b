"""The ``jobs`` table: queue, progress, verdicts -- and leases, so a job never runs twice.

A runner that starts a job takes a *lease* on it: its owner token and a time (epoch seconds)
until which the job is its own. While the worker runs, the runner renews the lease (a heartbeat
every third of its length); a renewal that finds the job no longer running under its token
(cancelled, or taken over) tells the runner to kill its worker. :meth:`JobTable.recover_jobs`
re-queues or fails a ``running`` job only once its lease has run out -- whoever ran it is gone
(and its worker with it: workers die with their server) -- so two servers on one store, or a
restarted server beside a survivor, never run one job at the same time.

Taking a job is one conditional ``UPDATE ... WHERE status = 'queued' RETURNING *``: of two runners
that try at once, one gets the row back and the other sees it taken, on SQLite (whose writers
serialise) as on PostgreSQL (where the second ``UPDATE`` waits for the first and re-checks the
condition). Taking back orphaned jobs reads them with ``FOR UPDATE SKIP LOCKED`` on PostgreSQL, so
two recovery passes never both re-queue one job (and so never re-queue one another runner has just
started). Lease times are epoch seconds from the clock of the process that writes them: processes
on several machines sharing one PostgreSQL store need clocks in step to well under a lease (NTP).

Rows without a lease (jobs started in-process by the command line, or by the first release)
fall back to the owner's process id: orphaned when that process is gone.
"""

from __future__ import annotations

import contextlib
import os
import time
import uuid
from datetime import UTC, datetime
from typing import Any

from app.errors import NotFoundError
from app.storage.dialect import Connection, Dialect
from app.storage.records import JobRecord, JobStatus


def now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _pid_alive(pid: int | None) -> bool:
    if pid is None or pid <= 0:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class JobTable:
    """Job rows of the store (mixed into it; it provides the connections and the dialect)."""

    dialect: Dialect

    def _conn(self) -> Connection:
        raise NotImplementedError

    def _tx(self) -> contextlib.AbstractContextManager[Connection]:
        raise NotImplementedError

    def _job(self, row: Any) -> JobRecord:
        return JobRecord(
            id=row["id"], kind=row["kind"], subject=row["subject"], status=JobStatus(row["status"]),
            progress=row["progress"], stage=row["stage"], attempts=row["attempts"], created_at=row["created_at"],
            updated_at=row["updated_at"], started_at=row["started_at"], finished_at=row["finished_at"],
            error_code=row["error_code"], error_detail=row["error_detail"], owner_pid=row["owner_pid"],
            lease_owner=row["lease_owner"], lease_until=row["lease_until"],
        )

    def _insert_job(self, db: Connection, kind: str, subject: str) -> str:
        job_id = f"job_{uuid.uuid4().hex[:16]}"
        ts = now()
        db.execute("INSERT INTO jobs (id, kind, subject, status, progress, stage, attempts, created_at, updated_at)"
                   " VALUES (?,?,?,?,0,'queued',0,?,?)", (job_id, kind, subject, JobStatus.QUEUED.value, ts, ts))
        return job_id

    def create_job(self, kind: str, subject: str) -> JobRecord:
        with self._tx() as db:
            job_id = self._insert_job(db, kind, subject)
        return self.get_job(job_id)

    def get_job(self, job_id: str) -> JobRecord:
        row = self._conn().execute("SELECT * FROM jobs WHERE id = ?", (job_id,)).fetchone()
        if row is None:
            raise NotFoundError(f"job {job_id!r} not found")
        return self._job(row)

    def find_job(self, kind: str, subject: str) -> JobRecord | None:
        row = self._conn().execute("SELECT * FROM jobs WHERE kind = ? AND subject = ? ORDER BY created_at DESC"
                                   " LIMIT 1", (kind, subject)).fetchone()
        return self._job(row) if row else None

    def start_job(self, job_id: str, owner: str | None = None, lease_s: float | None = None) -> JobRecord:
        """Mark a queued job running (with a lease of ``lease_s`` seconds for ``owner`` if given).

        A job no longer queued (cancelled, or started by another runner) is returned unchanged:
        the caller runs the job only if the returned record is running under its own lease.
        """
        until = time.time() + lease_s if lease_s is not None else None
        with self._tx() as db:
            taken = db.execute(
                "UPDATE jobs SET status = 'running', attempts = attempts + 1, started_at = ?, updated_at = ?,"
                " owner_pid = ?, progress = 0, stage = 'starting', error_code = NULL, error_detail = NULL,"
                " lease_owner = ?, lease_until = ? WHERE id = ? AND status = 'queued' RETURNING *",
                (now(), now(), os.getpid(), owner, until, job_id)).fetchall()
        return self._job(taken[0]) if taken else self.get_job(job_id)

    def renew_lease(self, job_id: str, owner: str, lease_s: float) -> bool:
        """Extend ``owner``'s lease; False when the job is no longer running under it (stop the worker)."""
        with self._tx() as db:
            cur = db.execute("UPDATE jobs SET lease_until = ? WHERE id = ? AND status = 'running' AND lease_owner = ?",
                             (time.time() + lease_s, job_id, owner))
        return cur.rowcount == 1

    def release_lease(self, job_id: str, owner: str) -> None:
        """Let the lease lapse now (a clean stop): the next start resumes the job without waiting, and the
        cut-off run does not count as an attempt (only a crash does)."""
        with self._tx() as db:
            db.execute("UPDATE jobs SET lease_until = 0,"
                       " attempts = CASE WHEN attempts > 0 THEN attempts - 1 ELSE 0 END, stage = ?, updated_at = ?"
                       " WHERE id = ? AND status = 'running' AND lease_owner = ?",
                       ("stopped with the server; resumes at the next start", now(), job_id, owner))

    def update_job(self, job_id: str, progress: float, stage: str) -> None:
        with self._tx() as db:
            db.execute("UPDATE jobs SET progress = ?, stage = ?, updated_at = ? WHERE id = ? AND status = 'running'",
                       (float(min(max(progress, 0.0), 1.0)), stage, now(), job_id))

    def finish_job(self, job_id: str) -> None:
        with self._tx() as db:
            db.execute("UPDATE jobs SET status = 'done', progress = 1, stage = 'done', finished_at = ?,"
                       " updated_at = ?, lease_until = NULL WHERE id = ?", (now(), now(), job_id))

    def fail_job(self, job_id: str, code: str, detail: str) -> None:
        with self._tx() as db:
            db.execute("UPDATE jobs SET status = 'failed', stage = 'failed', error_code = ?, error_detail = ?,"
                       " finished_at = ?, updated_at = ?, lease_until = NULL WHERE id = ?",
                       (code, detail, now(), now(), job_id))

    @staticmethod
    def _orphaned(row: Any, at: float) -> bool:
        if row["lease_until"] is not None:
            return bool(row["lease_until"] < at)
        return not _pid_alive(row["owner_pid"]) or row["owner_pid"] == os.getpid()

    def recover_jobs(self, max_attempts: int) -> list[JobRecord]:
        """Re-queue or fail running jobs whose owner is gone (lease run out); returns every queued job."""
        self.requeue_orphans(max_attempts)
        return self.pending_jobs()

    def requeue_orphans(self, max_attempts: int) -> list[JobRecord]:
        """Re-queue (or fail, past ``max_attempts``) running jobs whose lease has run out; returns the re-queued."""
        at = time.time()
        requeued: list[str] = []
        with self._tx() as db:
            running = db.execute("SELECT * FROM jobs WHERE status = 'running'" + self.dialect.lock_rows).fetchall()
            for row in running:
                if not self._orphaned(row, at):
                    continue  # its runner is alive and renewing the lease
                # "... AND status = 'running' AND attempts = ?": only the run that was read is taken back,
                # never one started since (each start counts an attempt), whatever the isolation level
                if row["attempts"] < max_attempts:
                    cur = db.execute("UPDATE jobs SET status = 'queued', stage = ?, updated_at = ?, lease_owner = NULL,"
                                     " lease_until = NULL WHERE id = ? AND status = 'running' AND attempts = ?",
                                     ("resumed after a clean stop" if row["lease_until"] == 0 else
                                      f"resumed after an interruption (attempt {row['attempts']} was cut off)", now(),
                                      row["id"], row["attempts"]))
                    if cur.rowcount == 1:
                        requeued.append(row["id"])
                else:
                    db.execute(
                        "UPDATE jobs SET status = 'failed', stage = 'failed', error_code = 'interrupted',"
                        " error_detail = ?, finished_at = ?, updated_at = ?, lease_until = NULL"
                        " WHERE id = ? AND status = 'running' AND attempts = ?",
                        (f"interrupted: the server stopped while this job was running, {row['attempts']} of "
                         f"{max_attempts} attempts used", now(), now(), row["id"], row["attempts"]))
        return [self.get_job(job_id) for job_id in requeued]

    def active_jobs(self, analysis_id: str) -> list[JobRecord]:
        """Queued or running jobs of an analysis: its own and its tolerance bands (``<id>/n=../seed=..``)."""
        rows = self._conn().execute(
            "SELECT * FROM jobs WHERE status IN ('queued', 'running') AND (subject = ? OR substr(subject, 1, ?) = ?)",
            (analysis_id, len(analysis_id) + 1, analysis_id + "/")).fetchall()
        return [self._job(r) for r in rows]

    def pending_jobs(self) -> list[JobRecord]:
        rows = self._conn().execute("SELECT * FROM jobs WHERE status = 'queued' ORDER BY created_at")
        return [self._job(r) for r in rows]

    def job_counts(self) -> dict[str, int]:
        rows = self._conn().execute("SELECT status, COUNT(*) AS n FROM jobs GROUP BY status")
        counts = {s.value: 0 for s in JobStatus}
        counts.update({r["status"]: r["n"] for r in rows})
        return counts
