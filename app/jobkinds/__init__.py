"""One module per kind of background job; each exposes ``run(store, job)``.

:class:`app.jobs.JobRunner` owns everything kinds share -- the queue, the worker process, the
wall-time limit, the lease, cancellation and the verdict -- and imports the kind's module in
the worker (``app.jobkinds.<kind>``). A new kind is a module here plus its lane in
:data:`app.jobs.KINDS`. :func:`progress_reporter` is the throttled progress callback every kind uses.
What a kind is asked and what it answers are artefacts of the store (``store.artifacts``,
:mod:`app.storage.artifacts`); the subjects below (the job row's ``subject``) are all the routes that
start a kind need from here, so the server never imports a kind's module.
"""

from __future__ import annotations

import time

from app.progress import Progress
from app.storage.base import Store

PROGRESS_EVERY_S = 0.25
DIAGNOSIS_SEP = "--dg"  # <analysis id><DIAGNOSIS_SEP><hex>: a diagnosis id names its analysis


def progress_reporter(store: Store, job_id: str, scale: float = 0.98) -> Progress:
    """A :class:`~app.progress.Progress` writing to the job row at most every 0.25 s (and at each new stage)."""
    last_time, last_stage = [0.0], [""]

    def progress(fraction: float, stage: str, /) -> None:
        now = time.monotonic()
        if stage != last_stage[0] or now - last_time[0] >= PROGRESS_EVERY_S:
            last_time[0], last_stage[0] = now, stage
            store.update_job(job_id, scale * fraction, stage)

    return progress


# -- job subjects: under an analysis (``<analysis id>/...``) the analysis' jobs include them, and deleting
# the analysis cancels them (app.storage.jobtable.JobTable.active_jobs)

def diagnosis_subject(analysis_id: str, diagnosis_id: str) -> str:
    return f"{analysis_id}/diagnoses/{diagnosis_id}"


def validation_subject(analysis_id: str, diagnosis_id: str) -> str:
    return f"{diagnosis_subject(analysis_id, diagnosis_id)}/validation"


def tolerance_subject(analysis_id: str, n: int, seed: int) -> str:
    """The job subject (and artefact id) of a tolerance band: ``<analysis>/n=<n>/seed=<seed>``."""
    return f"{analysis_id}/n={n}/seed={seed}"


def gap_sensitivity_subject(name: str, version: int) -> str:
    """The job subject (and artefact id) of a vehicle version's gap sensitivity: ``<name>/v<version>``."""
    return f"{name}/v{version}"
