"""Job kind ``validation``: does a diagnosed effect shrink the gap on another log too?

Subject: ``<analysis id>/diagnoses/<diagnosis id>/validation`` (:func:`app.jobkinds.validation_subject`):
under its analysis, so deleting the analysis cancels it. The diagnosis artefact's ``validation`` document
names the other log and the job (``log_id``, ``job_id``); the worker adds the shrink to it when done (one
atomic rewrite), so a re-run after a crash leaves one answer.
"""

from __future__ import annotations

from app.analysis.diagnosis import validate_effects
from app.diagnosis_decision import base_ratios, chosen
from app.errors import InputError
from app.jobkinds import progress_reporter
from app.jobkinds.diagnosis import KIND, decode, options
from app.storage.base import Store
from app.storage.records import JobRecord


def run(store: Store, job: JobRecord) -> None:
    diagnosis_id = job.subject.split("/")[2]
    art = store.artifacts
    report, st = art.get(KIND, diagnosis_id, "report"), art.get(KIND, diagnosis_id, "status")
    val = art.get(KIND, diagnosis_id, "validation")
    if report is None or st is None or val is None or "log_id" not in val:
        raise InputError(f"diagnosis {diagnosis_id} has no report or validation request", code="diagnosis_not_ready")
    effects = chosen(report)
    opts = options(report["options"], report["model"])
    progress = progress_reporter(store, job.id)
    progress(0.0, "decoding")
    signals, vehicle, read = decode(store, val["log_id"], st["vehicle"]["name"], st["vehicle"]["version"])
    result = validate_effects(effects, signals, vehicle, opts, progress,
                              base_ratios=base_ratios(report))
    art.put(KIND, diagnosis_id, "validation",
            {"log_id": val["log_id"], "job_id": val.get("job_id"), **result.to_dict(), "read": read})
