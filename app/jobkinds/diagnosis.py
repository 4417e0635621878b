"""Job kind ``diagnosis``: which unmodelled effect explains an analysis' sim-to-real gap.

Subject: ``<analysis id>/diagnoses/<diagnosis id>`` (:func:`app.jobkinds.diagnosis_subject`), so the
analysis' jobs (:meth:`app.storage.jobtable.JobTable.active_jobs`) include its diagnoses and validations
and deleting the analysis cancels them. The diagnosis is a ``diagnosis`` artefact of the store
(:mod:`app.storage.artifacts`): its ``status`` says what to run (options, vehicle) and which job runs it
(``job_id``) -- status, progress and errors live in the job row -- and the worker stores the ``report``,
the plots' numbers (``charts``) and the PNG plots, each atomically. A diagnosis is deterministic, so a
run resumed after a crash rewrites the same report.
"""

from __future__ import annotations

from typing import Any

from app.analysis.diagnosis import DiagnosisOptions, diagnose_checked, report_dict
from app.diagnosis_plots import chart_data, event_overlay_png, residual_chart_png
from app.errors import InputError
from app.jobkinds import progress_reporter
from app.pipeline import decode_log
from app.progress import within
from app.storage.base import Store
from app.storage.records import JobRecord
from sim import load_vehicle

KIND = "diagnosis"


def options(opts: dict[str, Any], model: str) -> DiagnosisOptions:
    """The stored options as :class:`app.analysis.diagnosis.DiagnosisOptions` (typed error if unreadable)."""
    try:
        return DiagnosisOptions(candidates=tuple(opts["candidates"]), seed=int(opts["seed"]), model=model)
    except (KeyError, TypeError) as exc:
        raise InputError(f"diagnosis options unreadable: {exc}") from exc


def decode(store: Store, log_id: str, vehicle_name: str, version: int) -> tuple[Any, Any, dict[str, Any]]:
    """A stored log's signals decoded with a stored vehicle's DBC and map, that vehicle's driveline, and what
    reading the log lost (``app.ingest.readreport``)."""
    logrec = store.get_log(log_id)
    veh = store.get_vehicle(vehicle_name, version)
    signals, ingest = decode_log(logrec.path, veh.database_path, veh.signal_map_path)
    return signals, load_vehicle(veh.driveline_path), ingest["read"]


def run(store: Store, job: JobRecord) -> None:
    analysis_id, _, diagnosis_id = job.subject.split("/")
    art = store.artifacts
    st = art.get(KIND, diagnosis_id, "status")
    if st is None:
        raise InputError(f"diagnosis {diagnosis_id} has no status", code="diagnosis_not_found")
    opts = options(st["options"], st["options"]["model"])
    progress = progress_reporter(store, job.id)
    progress(0.0, "decoding")
    rec = store.get_analysis(analysis_id)
    signals, vehicle, read = decode(store, rec.log_id, st["vehicle"]["name"], st["vehicle"]["version"])
    result, checked = diagnose_checked(signals, vehicle, opts,
                                       within(progress, 0.0, 0.95))
    doc = report_dict(result, findings=checked.findings)
    doc["read"] = read  # a damaged or truncated log, stated with the answer
    store.update_job(job.id, 0.97, "saving")
    if result.baseline is not None:
        with art.writing(KIND, diagnosis_id, "plot_events") as path:
            event_overlay_png(result, path)
        with art.writing(KIND, diagnosis_id, "plot_residual") as path:
            residual_chart_png(result, path)
        art.put(KIND, diagnosis_id, "charts", chart_data(result))
    art.put(KIND, diagnosis_id, "report", doc)
    art.update(KIND, diagnosis_id, "status", decision=doc["decision"]["status"])
