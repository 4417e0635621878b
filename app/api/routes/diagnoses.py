"""Diagnoses: which unmodelled effect explains an analysis' sim-to-real gap, and does it hold elsewhere.

::

    POST /analyses/{analysis_id}/diagnoses   {"candidates": [...], "seed": 0, "model": "multibody"}  -> 202
    GET  /diagnoses/{diagnosis_id}           status and progress; the report (lashscope.diagnosis/1) when done
    GET  /diagnoses/{diagnosis_id}/plots/{events|residual}   PNG
    POST /diagnoses/{diagnosis_id}/apply     {"name": optional}  -> 201 new vehicle version with the effect
    POST /diagnoses/{diagnosis_id}/validate  {"log_id": ...}     -> 202; shrink on that drive in the report

Work runs on a one-worker background pool (a diagnosis is CPU-bound). State lives in files under the
analysis' directory (``diagnoses/<id>/status.json``, ``report.json``, PNGs), so a finished diagnosis
survives a restart; one interrupted by a restart reads as failed.
"""

from __future__ import annotations

import json
import secrets
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

from fastapi import APIRouter, Request, status
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field

from app.api.deps import StoreDep
from app.api.schemas import ERRORS
from app.errors import AnalysisError, AppError, ConflictError, InputError, NotFoundError
from app.storage.base import Store
from sim.errors import SimError

router = APIRouter(tags=["diagnoses"], responses=ERRORS)

_SEP = "--dg"
PLOTS = {"events": "diagnosis_events.png", "residual": "diagnosis_residual.png"}


class DiagnosisCreate(BaseModel):
    candidates: list[str] | None = Field(default=None, description="effect ids; default: the whole library")
    seed: int = Field(default=0, ge=0, le=2**31 - 1, description="seed of the calibration/held-out split")
    model: str = Field(default="multibody", description="simulator model: multibody or two_inertia")


class ApplyBody(BaseModel):
    name: str | None = Field(default=None, description="vehicle name for the new version (default: the analysed one)")


class ValidateBody(BaseModel):
    log_id: str


class _Pool:
    def __init__(self) -> None:
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="diagnosis")


_POOL_LOCK = threading.Lock()


def _pool(request: Request) -> _Pool:
    """The app's diagnosis worker, created on first use."""
    state = request.app.state
    with _POOL_LOCK:
        if not hasattr(state, "diagnosis_pool"):
            state.diagnosis_pool = _Pool()
    pool: _Pool = state.diagnosis_pool
    return pool


def _dir(store: Store, diagnosis_id: str) -> Path:
    if _SEP not in diagnosis_id:
        raise NotFoundError(f"diagnosis {diagnosis_id!r} not found", code="diagnosis_not_found")
    analysis_id = diagnosis_id.rsplit(_SEP, 1)[0]
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    if not (d / "status.json").is_file():
        raise NotFoundError(f"diagnosis {diagnosis_id!r} not found", code="diagnosis_not_found")
    return d


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1, allow_nan=False, default=str), encoding="utf-8")
    tmp.replace(path)


def _status(d: Path, **kw: Any) -> None:
    path = d / "status.json"
    doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    doc.update(kw, updated_at=time.time())
    _write_json(path, doc)


def _run_guarded(d: Path, work: Any) -> None:
    try:
        work()
    except (AppError, SimError) as exc:
        _status(d, status="failed", error={"code": getattr(exc, "code", "error"), "detail": str(exc)})
    except Exception as exc:  # a bug must fail the diagnosis, not the server
        _status(d, status="failed", error={"code": "internal_error", "detail": f"{type(exc).__name__}: {exc}"})


def _decode(store: Store, log_id: str, vehicle_name: str, version: int) -> tuple[Any, Any]:
    from app.pipeline import decode_log
    from sim import load_vehicle

    logrec = store.get_log(log_id)
    veh = store.get_vehicle(vehicle_name, version)
    signals, _ = decode_log(logrec.path, veh.database_path, veh.signal_map_path)
    return signals, load_vehicle(veh.driveline_path)


@router.post("/analyses/{analysis_id}/diagnoses", status_code=status.HTTP_202_ACCEPTED,
             summary="Start a diagnosis of an analysis' sim-to-real gap (runs in the background)")
def create_diagnosis(analysis_id: str, body: DiagnosisCreate, store: StoreDep, request: Request) -> dict[str, Any]:
    from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals, report_dict
    from app.diagnosis_plots import event_overlay_png, residual_chart_png
    from sim.effects import EFFECTS

    rec = store.get_analysis(analysis_id)
    options = DiagnosisOptions(candidates=tuple(body.candidates) if body.candidates else tuple(EFFECTS),
                               seed=body.seed, model=body.model)  # 400 on unknown candidates or model
    diagnosis_id = f"{analysis_id}{_SEP}{secrets.token_hex(4)}"
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    d.mkdir(parents=True, exist_ok=True)
    _status(d, id=diagnosis_id, analysis_id=analysis_id, status="queued", progress=0.0, stage="queued",
            options={"candidates": list(options.candidates), "seed": options.seed, "model": options.model},
            vehicle={"name": rec.vehicle_name, "version": rec.vehicle_version})

    def work() -> None:
        _status(d, status="running", stage="decoding")
        signals, vehicle = _decode(store, rec.log_id, rec.vehicle_name, rec.vehicle_version)
        last = [0.0]

        def progress(fraction: float, message: str) -> None:
            if time.monotonic() - last[0] > 0.5 or fraction >= 1.0:
                last[0] = time.monotonic()
                _status(d, progress=round(0.95 * fraction, 3), stage=message)

        result = diagnose_signals(signals, vehicle, options, progress)
        doc = report_dict(result)
        if result.baseline is not None:
            event_overlay_png(result, d / PLOTS["events"])
            residual_chart_png(result, d / PLOTS["residual"])
        _write_json(d / "report.json", doc)
        _status(d, status="done", progress=1.0, stage="done", decision=doc["decision"]["status"])

    _pool(request).pool.submit(_run_guarded, d, work)
    return _read(d)


def _read(d: Path) -> dict[str, Any]:
    doc: dict[str, Any] = json.loads((d / "status.json").read_text(encoding="utf-8"))
    if doc.get("status") in ("queued", "running") and time.time() - doc.get("updated_at", 0) > 3600:
        doc["status"], doc["error"] = "failed", {"code": "interrupted", "detail": "no progress for an hour"}
    report = d / "report.json"
    if report.is_file():
        doc["report"] = json.loads(report.read_text(encoding="utf-8"))
    validation = d / "validation.json"
    if validation.is_file():
        doc["validation"] = json.loads(validation.read_text(encoding="utf-8"))
    doc["plots"] = [k for k, f in PLOTS.items() if (d / f).is_file()]
    return doc


@router.get("/diagnoses/{diagnosis_id}", summary="Status, progress and (when done) the diagnosis report")
def get_diagnosis(diagnosis_id: str, store: StoreDep) -> dict[str, Any]:
    return _read(_dir(store, diagnosis_id))


@router.get("/diagnoses/{diagnosis_id}/plots/{name}", summary="Per-event overlay or residual chart (PNG)",
            response_class=FileResponse)
def get_plot(diagnosis_id: str, name: str, store: StoreDep) -> FileResponse:
    d = _dir(store, diagnosis_id)
    if name not in PLOTS:
        raise NotFoundError(f"plot {name!r}: use one of {sorted(PLOTS)}", code="plot_not_found")
    path = d / PLOTS[name]
    if not path.is_file():
        raise ConflictError(f"diagnosis {diagnosis_id} has no {name} plot yet", code="diagnosis_not_ready")
    return FileResponse(path, media_type="image/png")


def _done_report(d: Path, diagnosis_id: str) -> dict[str, Any]:
    doc = _read(d)
    if doc.get("status") != "done" or "report" not in doc:
        raise ConflictError(f"diagnosis {diagnosis_id} is {doc.get('status')}", code="diagnosis_not_ready")
    report: dict[str, Any] = doc["report"]
    return report


def _chosen(report: dict[str, Any]) -> dict[str, dict[str, float]]:
    decision = report["decision"]
    key = "+".join(decision["top"])
    if not key or decision["status"] not in ("explained", "partial", "ambiguous"):
        raise AnalysisError(f"the diagnosis decided {decision['status']!r}: there is no effect to apply",
                            code="nothing_to_apply")
    for cand in report["candidates"] + report["pairs"]:
        if cand["id"] == key:
            params: dict[str, dict[str, float]] = cand["fit"]["params"]
            return params
    raise AnalysisError(f"candidate {key!r} is missing from the report", code="nothing_to_apply")


@router.post("/diagnoses/{diagnosis_id}/apply", status_code=status.HTTP_201_CREATED,
             summary="Apply the diagnosed effect: store a new vehicle version (the augmented model)")
def apply_diagnosis(diagnosis_id: str, body: ApplyBody, store: StoreDep) -> dict[str, Any]:
    from app.pipeline import check_vehicle_files
    from sim import dump_toml, load_vehicle
    from sim.effects import apply_effects

    d = _dir(store, diagnosis_id)
    report = _done_report(d, diagnosis_id)
    st = json.loads((d / "status.json").read_text(encoding="utf-8"))
    veh = store.get_vehicle(st["vehicle"]["name"], st["vehicle"]["version"])
    effects = _chosen(report)
    augmented = apply_effects(load_vehicle(veh.driveline_path), effects)
    name = body.name or veh.name
    path = d / f"{name}-augmented.toml"
    path.write_text(dump_toml(augmented), encoding="utf-8")
    summary = check_vehicle_files(path, veh.database_path, veh.signal_map_path)
    summary["diagnosis"] = {"id": diagnosis_id, "effects": effects, "from": f"{veh.name}@{veh.version}"}
    rec, created = store.add_vehicle(name, driveline=path, database=veh.database_path,
                                     signal_map=veh.signal_map_path, summary=summary)
    _status(d, applied={"vehicle": rec.name, "version": rec.version, "effects": effects})
    return {"vehicle": rec.name, "version": rec.version, "created": created, "effects": effects,
            "from": f"{veh.name}@{veh.version}"}


@router.post("/diagnoses/{diagnosis_id}/validate", status_code=status.HTTP_202_ACCEPTED,
             summary="Validate the diagnosed effect on another log (runs in the background)")
def validate_diagnosis(diagnosis_id: str, body: ValidateBody, store: StoreDep, request: Request) -> dict[str, Any]:
    from app.analysis.diagnosis import DiagnosisOptions, validate_effects

    d = _dir(store, diagnosis_id)
    report = _done_report(d, diagnosis_id)
    effects = _chosen(report)
    store.get_log(body.log_id)  # 404 now rather than in the background
    st = json.loads((d / "status.json").read_text(encoding="utf-8"))
    opts = report["options"]
    try:
        options = DiagnosisOptions(candidates=tuple(opts["candidates"]), seed=opts["seed"], model=report["model"])
    except (KeyError, TypeError) as exc:
        raise InputError(f"diagnosis report options unreadable: {exc}") from exc
    _write_json(d / "validation.json", {"status": "running", "log_id": body.log_id})

    def work() -> None:
        try:
            signals, vehicle = _decode(store, body.log_id, st["vehicle"]["name"], st["vehicle"]["version"])
            val = validate_effects(effects, signals, vehicle, options)
            _write_json(d / "validation.json", {"status": "done", "log_id": body.log_id, **val.to_dict()})
        except (AppError, SimError) as exc:
            _write_json(d / "validation.json", {"status": "failed", "log_id": body.log_id,
                                                "error": {"code": getattr(exc, "code", "error"), "detail": str(exc)}})

    _pool(request).pool.submit(_run_guarded, d, work)
    return _read(d)
