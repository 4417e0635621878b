"""Background execution of analyses: a small thread pool fed from the store's jobs table.

The store is the source of truth: a job is queued in SQLite before it is submitted here,
marked running (with this process id) when a worker picks it up, and finished or failed
with a typed ``{code, detail}`` when it ends. At startup :meth:`JobRunner.start` asks the
store to re-queue (or fail, after ``max_attempts``) jobs cut off by a crash and runs every
queued job, so nothing is lost across restarts.
"""

from __future__ import annotations

import logging
import threading
import time
from concurrent.futures import Future, ThreadPoolExecutor

from app.errors import AppError
from app.payload import result_payload
from app.pipeline import AnalysisOptions, VehicleInputs, run_analysis
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import write_result
from sim import SimError, load_vehicle

log = logging.getLogger("lashscope.jobs")
PROGRESS_EVERY_S = 0.25


class JobRunner:
    def __init__(self, store: Store, workers: int = 1, max_attempts: int = 2) -> None:
        self.store = store
        self.max_attempts = max_attempts
        self._pool = ThreadPoolExecutor(max_workers=workers, thread_name_prefix="lashscope-job")
        self._futures: dict[str, Future[None]] = {}
        self._lock = threading.Lock()
        self._closed = False

    def start(self) -> list[JobRecord]:
        """Recover interrupted jobs and submit every queued one; returns what was submitted."""
        pending = self.store.recover_jobs(self.max_attempts)
        for job in pending:
            self.submit(job.id)
        return pending

    def submit(self, job_id: str) -> None:
        with self._lock:
            if self._closed or job_id in self._futures:
                return
            self._futures[job_id] = self._pool.submit(self._run, job_id)

    def wait(self, job_id: str, timeout: float | None = None) -> None:
        with self._lock:
            fut = self._futures.get(job_id)
        if fut is not None:
            fut.result(timeout)

    def shutdown(self, wait: bool = False) -> None:
        with self._lock:
            self._closed = True
        self._pool.shutdown(wait=wait, cancel_futures=True)

    # -- one job ---------------------------------------------------------------------------
    def _run(self, job_id: str) -> None:
        try:
            job = self.store.start_job(job_id)
            if job.kind != "analysis":
                raise AppError(f"unknown job kind {job.kind!r}", code="unknown_job")
            self._analysis(job)
            self.store.finish_job(job_id)
        except (AppError, SimError) as exc:
            self.store.fail_job(job_id, getattr(exc, "code", "error"), str(exc))
        except MemoryError:
            self.store.fail_job(job_id, "out_of_memory", "the analysis ran out of memory")
        except Exception as exc:  # a bug must fail the job, not the server
            log.exception("job %s failed", job_id)
            self.store.fail_job(job_id, "internal_error", f"{type(exc).__name__}: {exc}")
        finally:
            with self._lock:
                self._futures.pop(job_id, None)

    def _analysis(self, job: JobRecord) -> None:
        rec = self.store.get_analysis(job.subject)
        logrec = self.store.get_log(rec.log_id)
        veh = self.store.get_vehicle(rec.vehicle_name, rec.vehicle_version)
        last_time, last_stage = [0.0], [""]

        def progress(stage: str, fraction: float) -> None:
            now = time.monotonic()
            if stage != last_stage[0] or now - last_time[0] >= PROGRESS_EVERY_S:
                last_time[0], last_stage[0] = now, stage
                self.store.update_job(job.id, 0.98 * fraction, stage)

        inputs = VehicleInputs(load_vehicle(veh.driveline_path), veh.database_path, veh.signal_map_path)
        result = run_analysis(logrec.path, inputs, AnalysisOptions.from_dict(rec.options), progress)
        self.store.update_job(job.id, 0.99, "saving")
        doc, arrays = result_payload(result)
        write_result(rec.result_dir, doc, arrays)
        self.store.set_analysis_summary(rec.id, doc["summary"])
