"""Background jobs (analyses, tolerance bands, diagnoses, validations, batches): the one job runner.

Every kind runs here, in its own worker process with a wall-time limit, under a lease; a kind is
a module in :mod:`app.jobkinds` and a lane in :data:`KINDS`.

The store is the source of truth: a job is queued in SQLite before it is submitted here,
marked running under this runner's lease (renewed while the worker runs, see
:mod:`app.storage.jobtable`) when a runner thread picks it up, and finished
or failed with a typed ``{code, detail}`` when it ends. At startup :meth:`JobRunner.start`
asks the store to re-queue (or fail, after ``max_attempts``) jobs cut off by a crash and runs
every queued job, so nothing is lost across restarts.

Why a process per job: the simulator holds the GIL in long compiled loops, so a runaway job in
a thread of the server would stall every request, ``/health`` included. A spawned worker
process is isolated: the runner thread only waits on it, kills it after ``timeout_s`` (the job
fails with ``timed out after N s``) and fails the job if the process dies without a verdict
(e.g. out of memory). The worker reports progress and its result through the store, which is
safe across processes. ``in_process=True`` runs jobs in the runner thread instead (for the
command line, where nothing else has to stay responsive).

Lanes: analyses, tolerance bands and gap sensitivities share the ``analysis`` lane (``workers`` at a time); the long
kinds -- diagnoses, validations, batches, minutes each -- run one at a time in the ``long`` lane, so
a whole-library fit never holds up a new analysis. Workers run at a lower OS priority
(:data:`WORKER_NICE`), so on a small machine the scheduler serves request handling first.
"""

from __future__ import annotations

import contextlib
import logging
import math
import multiprocessing
import os
import socket
import threading
import time
import uuid
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from importlib import import_module
from multiprocessing.process import BaseProcess

from app.errors import AppError
from app.storage.base import Store
from app.storage.records import JobRecord, JobStatus
from app.storage.url import open_store
from app.tempfiles import temp_dir_of
from app.worker import die_with_parent
from sim import SimError

log = logging.getLogger("lashscope.jobs")
#: kind -> lane; one module each in app.jobkinds, with run(store, job)
KINDS = {"analysis": "analysis", "tolerance": "analysis", "diagnosis": "long", "validation": "long",
         "batch": "long", "identification": "long", "gap_sensitivity": "analysis"}
WORKER_NICE = 5  # added to a worker's niceness: the API's reads come first on a busy machine
_SPAWN = multiprocessing.get_context("spawn")  # no fork of a threaded server; the child imports afresh


class JobRunner:
    """Runs queued jobs, ``workers`` at a time, each in a spawned worker process under a lease.

    ``lease_s``: how long a job stays this runner's without a heartbeat (renewed every third of it);
    after a crash of the whole server the job is resumed once that has run out. A background loop
    re-checks the store every half lease and resumes jobs whose runner is gone. ``timeouts``: a
    kind's own wall time (s) and the setting that names it, instead of ``timeout_s``
    (``LASHSCOPE_JOB_TIMEOUT_S``).
    """

    def __init__(self, store: Store, workers: int = 1, max_attempts: int = 2, timeout_s: float | None = 600.0,
                 in_process: bool = False, lease_s: float = 10.0,
                 timeouts: dict[str, tuple[float, str]] | None = None) -> None:
        self.store = store
        self.max_attempts = max_attempts
        self.timeout_s = timeout_s
        self.timeouts = dict(timeouts or {})
        self.in_process = in_process
        self.lease_s = lease_s
        self.owner = f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"
        self._pools = {"analysis": ThreadPoolExecutor(max_workers=workers, thread_name_prefix="lashscope-job"),
                       "long": ThreadPoolExecutor(max_workers=1, thread_name_prefix="lashscope-long-job")}
        self._futures: dict[str, Future[None]] = {}
        self._procs: dict[str, BaseProcess] = {}
        self._lock = threading.Lock()
        self._closed = False
        self._stop = threading.Event()
        self._cancelled: set[str] = set()
        # called in the runner thread with each job that finished done (the API warms its readers of the
        # result there, so the first dashboard view after an analysis does not pay for it); errors are logged
        self.on_done: list[Callable[[JobRecord], None]] = []

    def start(self) -> list[JobRecord]:
        """Recover interrupted jobs and submit every queued one; returns what was submitted.

        Then, every half lease in a daemon thread, resumes jobs of a crashed runner once their lease has
        run out."""
        pending = self.recover()
        if not self.in_process:
            threading.Thread(target=self._watch, name="lashscope-job-watch", daemon=True).start()
        return pending

    def recover(self) -> list[JobRecord]:
        pending = self.store.recover_jobs(self.max_attempts)
        for job in pending:
            self.submit(job.id)
        return pending

    def _watch(self) -> None:
        """Resume jobs whose runner died (their lease ran out) -- only those: a queued job is run by
        whoever queued it (or at the next start), so rows another part of the service keeps queued
        for its own reasons are left alone."""
        while not self._stop.wait(self.lease_s / 2):
            try:
                for job in self.store.requeue_orphans(self.max_attempts):
                    self.submit(job.id)
            except Exception:  # a locked or vanished store must not end the loop
                log.exception("job recovery pass failed")

    def submit(self, job_id: str) -> None:
        lane = KINDS.get(self.store.get_job(job_id).kind, "analysis")  # an unknown kind fails in _run
        with self._lock:
            if self._closed or job_id in self._futures:
                return
            self._futures[job_id] = self._pools[lane].submit(self._run, job_id)

    def wait(self, job_id: str, timeout: float | None = None) -> None:
        with self._lock:
            fut = self._futures.get(job_id)
        if fut is not None:
            fut.result(timeout)

    def cancel(self, job_id: str, reason: str) -> None:
        """Stop a job for good: a queued one never starts, a running one's worker is killed.

        The job fails with code ``cancelled`` before the worker is killed, so the runner thread that
        waits on it sees a verdict and records no ``worker_died``.
        """
        with self._lock:
            self._cancelled.add(job_id)
            fut, proc = self._futures.get(job_id), self._procs.get(job_id)
        self.store.fail_job(job_id, "cancelled", reason)
        if fut is not None:
            fut.cancel()
        if proc is not None:
            proc.kill()

    def shutdown(self, wait: bool = False) -> None:
        """Take no new work; kill running workers (their jobs stay 'running' with the lease let go and the
        attempt not counted, so the next start resumes them at once)."""
        self._stop.set()
        with self._lock:
            self._closed = True
            procs = dict(self._procs)
        if not wait:
            for job_id, p in procs.items():
                p.kill()
                p.join(5.0)
                self.store.release_lease(job_id, self.owner)
        for pool in self._pools.values():
            # with the workers killed, the pool threads return at once; they are joined (unless jobs run in
            # them) so that nobody closes the store under a thread still reading it
            pool.shutdown(wait=wait or not self.in_process, cancel_futures=True)

    # -- one job ---------------------------------------------------------------------------
    def _run(self, job_id: str) -> None:
        try:
            job = self.store.start_job(job_id, self.owner, None if self.in_process else self.lease_s)
            if job.status is not JobStatus.RUNNING or job.lease_owner != self.owner or job_id in self._cancelled:
                return  # cancelled, or taken by another runner, while it waited
            if job.kind not in KINDS:
                self.store.fail_job(job_id, "unknown_job", f"unknown job kind {job.kind!r}")
            elif self.in_process:
                execute(self.store, job)
            else:
                self._in_worker(job)
            self._done(job_id)
        except Exception as exc:  # a bug must fail the job, not the server
            log.exception("job %s failed", job_id)
            self.store.fail_job(job_id, "internal_error", f"{type(exc).__name__}: {exc}")
        finally:
            with self._lock:
                self._futures.pop(job_id, None)
                self._procs.pop(job_id, None)

    def _done(self, job_id: str) -> None:
        if not self.on_done:
            return
        job = self.store.get_job(job_id)
        if job.status is not JobStatus.DONE:
            return
        for hook in self.on_done:
            try:
                hook(job)
            except Exception:  # the job is done whatever a hook does
                log.exception("after job %s: %r failed", job_id, hook)

    def _supervise(self, job: JobRecord, proc: BaseProcess) -> bool:
        """Wait for the worker, renewing the lease; kill it past the wall time or when the lease is lost
        (the job was cancelled or taken over). False: the runner has dealt with the job already."""
        timeout_s, setting = self.timeouts.get(job.kind, (self.timeout_s, "LASHSCOPE_JOB_TIMEOUT_S"))
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while True:
            left = None if deadline is None else deadline - time.monotonic()
            proc.join(self.lease_s / 3 if left is None else max(0.0, min(self.lease_s / 3, left)))
            if not proc.is_alive():
                return True
            if deadline is not None and time.monotonic() >= deadline:
                proc.kill()
                proc.join()
                self.store.fail_job(job.id, "timeout", f"timed out after {timeout_s:g} s "
                                    f"({setting}); the worker was stopped")
                log.warning("job %s timed out after %g s", job.id, timeout_s)
                return False
            with self._lock:  # never renewed after shutdown() let the lease go (it sets _closed first)
                renewed = self._closed or self.store.renew_lease(job.id, self.owner, self.lease_s)
            if not renewed:
                proc.kill()
                proc.join()
                log.warning("job %s is no longer this runner's (cancelled or taken over); worker stopped", job.id)
                return False

    def _in_worker(self, job: JobRecord) -> None:
        proc = _SPAWN.Process(target=worker_main, args=(self.store.url, job.id, os.getpid()), daemon=True,
                              name=f"lashscope-{job.kind}-{job.id}")
        with self._lock:
            if self._closed:
                self.store.release_lease(job.id, self.owner)  # re-queued at the next start
                return
            proc.start()
            self._procs[job.id] = proc
        try:
            supervised = self._supervise(job, proc)
        finally:
            self.store.clean_temp(math.inf)  # what the worker left if it was killed (its process is gone now)
        if not supervised:
            return
        with self._lock:
            closed = self._closed
        if self.store.get_job(job.id).status is JobStatus.RUNNING and not closed:
            code = proc.exitcode
            reason = f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            self.store.fail_job(job.id, "worker_died", f"the worker process ended without a result ({reason})")


def worker_main(url: str, job_id: str, parent: int | None = None) -> None:
    """Entry point of a worker process: run one job against the store at ``url``; dies with ``parent``."""
    if parent is not None:
        die_with_parent(parent)
        with contextlib.suppress(OSError):
            os.nice(WORKER_NICE)
    store = open_store(url)
    try:
        with temp_dir_of(store.root):
            execute(store, store.get_job(job_id))
    finally:
        store.close()


def execute(store: Store, job: JobRecord) -> None:
    """Run a started job and record its outcome (done, or failed with a typed reason)."""
    try:
        run = import_module(f"app.jobkinds.{job.kind}").run  # KINDS only: checked before a worker starts
        run(store, job)
        store.finish_job(job.id)
    except (AppError, SimError) as exc:
        store.fail_job(job.id, getattr(exc, "code", "error"), _user_names(store, job, str(exc)))
    except MemoryError:
        store.fail_job(job.id, "out_of_memory", "the job ran out of memory")
    except Exception as exc:  # a bug must fail the job, not the worker silently
        log.exception("job %s failed", job.id)
        store.fail_job(job.id, "internal_error", f"{type(exc).__name__}: {exc}")


def _user_names(store: Store, job: JobRecord, message: str) -> str:
    """``message`` with the stored log's internal file name replaced by the name it was uploaded as."""
    try:
        rec = store.get_analysis(job.subject.split("/", 1)[0])
        logrec = store.get_log(rec.log_id)
    except AppError:
        return message
    return message.replace(str(logrec.path), logrec.filename).replace(logrec.path.name, logrec.filename)
