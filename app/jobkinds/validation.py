"""Job kind ``validation``: does a diagnosed effect shrink the gap on another log too?

Subject: ``<analysis id>/diagnoses/<diagnosis id>/validation`` (:func:`subject`): under its
analysis, so deleting the analysis cancels it. ``validation.json`` in the diagnosis' directory
names the other log and the job (``log_id``, ``job_id``); the worker adds the shrink to it when
done (one atomic rewrite), so a re-run after a crash leaves one answer.
"""

from __future__ import annotations

from app.errors import InputError
from app.jobkinds import progress_reporter
from app.jobkinds.diagnosis import (
    REPORT,
    STATUS,
    VALIDATION,
    base_ratios,
    chosen,
    decode,
    options,
    read_json,
    write_json,
)
from app.jobkinds.diagnosis import subject as diagnosis_subject
from app.storage.base import Store
from app.storage.records import JobRecord


def subject(analysis_id: str, diagnosis_id: str) -> str:
    return f"{diagnosis_subject(analysis_id, diagnosis_id)}/validation"


def run(store: Store, job: JobRecord) -> None:
    from app.analysis.diagnosis import validate_effects  # lazy: the diagnosis library loads in the worker only

    analysis_id, _, diagnosis_id, _ = job.subject.split("/")
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    report, st, val = read_json(d / REPORT), read_json(d / STATUS), read_json(d / VALIDATION)
    if report is None or st is None or val is None or "log_id" not in val:
        raise InputError(f"diagnosis {diagnosis_id} has no report or validation request", code="diagnosis_not_ready")
    effects = chosen(report)
    opts = options(report["options"], report["model"])
    progress = progress_reporter(store, job.id)
    progress(0.0, "decoding")
    signals, vehicle, read = decode(store, val["log_id"], st["vehicle"]["name"], st["vehicle"]["version"])
    result = validate_effects(effects, signals, vehicle, opts, progress,
                              base_ratios=base_ratios(report))
    write_json(d / VALIDATION, {"log_id": val["log_id"], "job_id": val.get("job_id"), **result.to_dict(), "read": read})
