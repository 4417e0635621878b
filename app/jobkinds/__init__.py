"""One module per kind of background job; each exposes ``run(store, job)``.

:class:`app.jobs.JobRunner` owns everything kinds share -- the queue, the worker process, the
wall-time limit, the lease, cancellation and the verdict -- and imports the kind's module in
the worker (``app.jobkinds.<kind>``). A new kind is a module here plus its lane in
:data:`app.jobs.KINDS`. :func:`progress_reporter` is the throttled progress callback every kind uses.
"""

from __future__ import annotations

import time

from app.progress import Progress
from app.storage.base import Store

PROGRESS_EVERY_S = 0.25


def progress_reporter(store: Store, job_id: str, scale: float = 0.98) -> Progress:
    """A :class:`~app.progress.Progress` writing to the job row at most every 0.25 s (and at each new stage)."""
    last_time, last_stage = [0.0], [""]

    def progress(fraction: float, stage: str, /) -> None:
        now = time.monotonic()
        if stage != last_stage[0] or now - last_time[0] >= PROGRESS_EVERY_S:
            last_time[0], last_stage[0] = now, stage
            store.update_job(job_id, scale * fraction, stage)

    return progress
