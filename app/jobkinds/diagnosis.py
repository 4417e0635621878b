"""Job kind ``diagnosis``: which unmodelled effect explains an analysis' sim-to-real gap.

Subject: ``<analysis id>/diagnoses/<diagnosis id>`` (:func:`subject`), so the analysis' jobs
(:meth:`app.storage.jobtable.JobTable.active_jobs`) include its diagnoses and validations and
deleting the analysis cancels them. The diagnosis' files live in
``<analysis dir>/diagnoses/<diagnosis id>/``: ``status.json`` says what to run (options,
vehicle) and which job runs it (``job_id``) -- status, progress and errors live in the job row --
and the worker writes ``report.json`` and the PNG plots there, each atomically. A diagnosis is
deterministic, so a run resumed after a crash rewrites the same report.
"""

from __future__ import annotations

import json
import threading
from pathlib import Path
from typing import Any

from app import atomic
from app.errors import AnalysisError, InputError
from app.jobkinds import progress_reporter
from app.pipeline import decode_log
from app.progress import within
from app.storage.base import Store
from app.storage.records import JobRecord
from sim import load_vehicle

SEP = "--dg"  # <analysis id><SEP><hex>: a diagnosis id names its analysis
STATUS, VALIDATION, REPORT = "status.json", "validation.json", "report.json"
PLOTS = {"events": "diagnosis_events.png", "residual": "diagnosis_residual.png"}
CHARTS = "charts.json"  # the plots' numbers for the dashboard (app.diagnosis_plots.chart_data)
_FILE_LOCK = threading.Lock()


def subject(analysis_id: str, diagnosis_id: str) -> str:
    return f"{analysis_id}/diagnoses/{diagnosis_id}"


def directory(store: Store, diagnosis_id: str) -> Path:
    """Where a diagnosis' files are (whether or not they exist)."""
    return store.analysis_dir(diagnosis_id.rsplit(SEP, 1)[0]) / "diagnoses" / diagnosis_id


def write_json(path: Path, doc: dict[str, Any]) -> None:
    """Write ``doc`` to a temporary sibling and rename it into place: a reader never sees half a file."""
    write_text(path, json.dumps(doc, indent=1, allow_nan=False, default=str))


def write_text(path: Path, text: str) -> None:
    """Write ``text`` to a temporary sibling and rename it into place (:func:`app.atomic.write_text`)."""
    atomic.write_text(path, text)


def read_json(path: Path) -> dict[str, Any] | None:
    if not path.is_file():
        return None
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return doc


def update(path: Path, **kw: Any) -> dict[str, Any]:
    """Merge ``kw`` into a JSON file (atomic replace); returns the new content."""
    with _FILE_LOCK:
        doc = read_json(path) or {}
        doc.update(kw)
        write_json(path, doc)
    return doc


def options(opts: dict[str, Any], model: str) -> Any:
    """The stored options as :class:`app.analysis.diagnosis.DiagnosisOptions` (typed error if unreadable)."""
    from app.analysis.diagnosis import DiagnosisOptions  # lazy: the server imports this module for file names

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


def chosen(report: dict[str, Any]) -> dict[str, dict[str, float]]:
    """The fitted parameters of the effect (or pair) a report decided on ({} when it decided on base parameters
    alone, see :func:`base_ratios`); typed error when there is nothing to apply."""
    decision = report["decision"]
    key = "+".join(decision["top"])
    if decision["status"] == "base_parameters":
        if decision.get("identify_first"):
            raise AnalysisError("the diagnosis stopped at a prior bound of a base parameter: identify the vehicle "
                                "first (lashscope identify, or POST /identifications)", code="nothing_to_apply")
        return {}
    if not key or decision["status"] not in ("explained", "partial", "ambiguous"):
        raise AnalysisError(f"the diagnosis decided {decision['status']!r}: there is no effect to apply",
                            code="nothing_to_apply")
    for cand in report["candidates"] + report["pairs"]:
        if cand["id"] == key:  # the base parameters fitted with it are applied from base_ratios
            return {k: v for k, v in cand["fit"]["params"].items() if k in decision["top"]}
    raise AnalysisError(f"candidate {key!r} is missing from the report", code="nothing_to_apply")


def base_ratios(report: dict[str, Any]) -> dict[str, float]:
    """The identified base parameters (ratios to the file's values) the decision rests on; {} when none."""
    if not report["decision"].get("base_parameters"):
        return {}
    ratios: dict[str, float] = (report.get("identification") or {}).get("ratios") or {}
    return dict(ratios)


def run(store: Store, job: JobRecord) -> None:
    from app.analysis.diagnosis import diagnose_checked, report_dict  # lazy: in the worker only
    from app.diagnosis_plots import chart_data, event_overlay_png, residual_chart_png  # lazy: matplotlib

    analysis_id, _, diagnosis_id = job.subject.split("/")
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    st = read_json(d / STATUS)
    if st is None:
        raise InputError(f"diagnosis {diagnosis_id} has no {STATUS}", code="diagnosis_not_found")
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
        event_overlay_png(result, d / PLOTS["events"])
        residual_chart_png(result, d / PLOTS["residual"])
        write_json(d / CHARTS, chart_data(result))
    write_json(d / REPORT, doc)
    update(d / STATUS, decision=doc["decision"]["status"])
