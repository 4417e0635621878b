"""Diagnoses: which unmodelled effect explains an analysis' sim-to-real gap, and does it hold elsewhere.

::

    POST /analyses/{analysis_id}/diagnoses   {"candidates": [...], "seed": 0, "model": "multibody"}  -> 202
    GET  /diagnoses/{diagnosis_id}           status and progress; the report (lashscope.diagnosis/1) when done
    GET  /diagnoses/{diagnosis_id}/plots/{events|residual}   PNG
    POST /diagnoses/{diagnosis_id}/apply     {"name": optional}  -> 201 new vehicle version with the effect
    POST /diagnoses/{diagnosis_id}/validate  {"log_id": ...}     -> 202; shrink on that drive in the report

Work runs one piece at a time, each in its own spawned worker process killed after
``LASHSCOPE_DIAGNOSIS_TIMEOUT_S`` (the diagnosis then fails with code ``timeout``), so a CPU-bound fit
never slows request handling and a runaway one is stopped. State lives in files under the
analysis' directory (``diagnoses/<id>/status.json``, ``report.json``, ``validation.json``, PNGs), so a
finished diagnosis survives a restart, and one cut off by a restart is resumed when the server
starts again -- or, after it has been cut off twice, marked failed with the reason "interrupted by
server restart" (:mod:`app.diagnosis_state`; the router's lifespan runs the recovery after the
app's own, so the store exists). The status carries ``attempts``.
"""

from __future__ import annotations

import json
import secrets
import time
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import asynccontextmanager
from functools import partial
from pathlib import Path
from typing import Any

from fastapi import APIRouter, FastAPI, Request, status
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field

from app.api.deps import StoreDep
from app.api.schemas import ERRORS, AppliedOut, DiagnosisOut
from app.diagnosis_state import ACTIVE, Check, Work, Worker, log, recover, state, update, write_json
from app.errors import AnalysisError, ConflictError, InputError, NotFoundError
from app.storage.base import Store

_SEP = "--dg"
PLOTS = {"events": "diagnosis_events.png", "residual": "diagnosis_residual.png"}
STATUS, VALIDATION = "status.json", "validation.json"


class DiagnosisCreate(BaseModel):
    candidates: list[str] | None = Field(default=None, description="effect ids; default: the whole library")
    seed: int = Field(default=0, ge=0, le=2**31 - 1, description="seed of the calibration/held-out split")
    model: str = Field(default="multibody", description="simulator model: multibody or two_inertia")


class ApplyBody(BaseModel):
    name: str | None = Field(default=None, description="vehicle name for the new version (default: the analysed one)")


class ValidateBody(BaseModel):
    log_id: str


def _new_worker(app: FastAPI) -> Worker:
    settings = getattr(app.state, "settings", None)
    return Worker(timeout_s=settings.diagnosis_timeout_s if settings is not None else None)


def _worker(app: FastAPI) -> Worker:
    """The app's diagnosis worker (made by the lifespan; on first use when the app runs without one)."""
    worker: Worker | None = getattr(app.state, "diagnosis_worker", None)
    if worker is None:
        worker = app.state.diagnosis_worker = _new_worker(app)
    return worker


def _diagnosis_dirs(store: Store) -> Iterator[Path]:
    offset, page_size = 0, 200
    while True:
        page = store.list_analyses(limit=page_size, offset=offset)
        for rec in page:
            root = store.analysis_dir(rec.id) / "diagnoses"
            if root.is_dir():
                yield from sorted(p for p in root.iterdir() if (p / STATUS).is_file())
        if len(page) < page_size:
            return
        offset += page_size


def recover_interrupted(store: Store, worker: Worker) -> dict[str, list[str]]:
    """Resume (or fail) every diagnosis and validation cut off by a stop or crash (see :mod:`app.diagnosis_state`)."""
    todo: list[tuple[str, Path, Callable[[], Work]]] = []
    for d in _diagnosis_dirs(store):
        todo.append((d.name, d / STATUS, partial(_diagnosis_work, store, d)))
        todo.append((f"{d.name}/validation", d / VALIDATION, partial(_validation_work, store, d)))
    return recover(todo, worker)


@asynccontextmanager
async def lifespan(app: FastAPI) -> AsyncIterator[None]:
    """Resume interrupted work at startup; ask the running work to stop at shutdown (it goes back to the queue)."""
    worker = app.state.diagnosis_worker = _new_worker(app)
    store: Store | None = getattr(app.state, "store", None)
    if store is not None:
        done = recover_interrupted(store, worker)
        if done["resumed"] or done["failed"]:
            log.info("diagnoses after a restart: resumed %s, failed %s", done["resumed"], done["failed"])
    try:
        yield
    finally:
        worker.close()
        app.state.diagnosis_worker = None


router = APIRouter(tags=["diagnoses"], responses=ERRORS, lifespan=lifespan)


def _dir(store: Store, diagnosis_id: str) -> Path:
    if _SEP not in diagnosis_id:
        raise NotFoundError(f"diagnosis {diagnosis_id!r} not found", code="diagnosis_not_found")
    analysis_id = diagnosis_id.rsplit(_SEP, 1)[0]
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    if not (d / STATUS).is_file():
        raise NotFoundError(f"diagnosis {diagnosis_id!r} not found", code="diagnosis_not_found")
    return d


def _decode(store: Store, log_id: str, vehicle_name: str, version: int) -> tuple[Any, Any]:
    from app.pipeline import decode_log
    from sim import load_vehicle

    logrec = store.get_log(log_id)
    veh = store.get_vehicle(vehicle_name, version)
    signals, _ = decode_log(logrec.path, veh.database_path, veh.signal_map_path)
    return signals, load_vehicle(veh.driveline_path)


def _options(opts: dict[str, Any], model: str) -> Any:
    from app.analysis.diagnosis import DiagnosisOptions

    try:
        return DiagnosisOptions(candidates=tuple(opts["candidates"]), seed=int(opts["seed"]), model=model)
    except (KeyError, TypeError) as exc:
        raise InputError(f"diagnosis options unreadable: {exc}") from exc


def _diagnosis_work(store: Store, d: Path) -> Work:
    """The diagnosis ``d/status.json`` describes (options, analysis, vehicle), as work for the worker process."""
    st = json.loads((d / STATUS).read_text(encoding="utf-8"))
    _options(st["options"], st["options"]["model"])  # unreadable options fail now, not in the worker
    return partial(_run_diagnosis, store.url, str(d))


def _in_store(url: str, run: Callable[[Store], None]) -> None:
    """Run ``run`` against the store at ``url`` (the worker process opens its own connection)."""
    from app.storage.url import open_store

    store = open_store(url)
    try:
        run(store)
    finally:
        store.close()


def _run_diagnosis(root: str, dir_: str, check: Check) -> None:
    """Worker-process side of a diagnosis: decode, fit with progress in ``status.json``, write report and plots."""
    from app.analysis.diagnosis import diagnose_signals, report_dict
    from app.diagnosis_plots import event_overlay_png, residual_chart_png

    d = Path(dir_)
    path = d / STATUS
    st = json.loads(path.read_text(encoding="utf-8"))
    options = _options(st["options"], st["options"]["model"])

    def run(store: Store) -> None:
        update(path, status="running", stage="decoding", progress=0.0)
        rec = store.get_analysis(st["analysis_id"])
        signals, vehicle = _decode(store, rec.log_id, st["vehicle"]["name"], st["vehicle"]["version"])
        last = [0.0]

        def progress(fraction: float, message: str) -> None:
            check()
            if time.monotonic() - last[0] > 0.5 or fraction >= 1.0:
                last[0] = time.monotonic()
                update(path, progress=round(0.95 * fraction, 3), stage=message)

        result = diagnose_signals(signals, vehicle, options, progress)
        doc = report_dict(result)
        if result.baseline is not None:
            event_overlay_png(result, d / PLOTS["events"])
            residual_chart_png(result, d / PLOTS["residual"])
        write_json(d / "report.json", doc)
        update(path, status="done", progress=1.0, stage="done", decision=doc["decision"]["status"], owner=None)

    _in_store(root, run)


@router.post("/analyses/{analysis_id}/diagnoses", status_code=status.HTTP_202_ACCEPTED, response_model=DiagnosisOut,
             summary="Start a diagnosis of an analysis' sim-to-real gap (runs in the background)")
def create_diagnosis(analysis_id: str, body: DiagnosisCreate, store: StoreDep, request: Request) -> dict[str, Any]:
    from app.analysis.diagnosis import DiagnosisOptions
    from sim.effects import EFFECTS

    rec = store.get_analysis(analysis_id)
    options = DiagnosisOptions(candidates=tuple(body.candidates) if body.candidates else tuple(EFFECTS),
                               seed=body.seed, model=body.model)  # 400 on unknown candidates or model
    diagnosis_id = f"{analysis_id}{_SEP}{secrets.token_hex(4)}"
    d = store.analysis_dir(analysis_id) / "diagnoses" / diagnosis_id
    d.mkdir(parents=True, exist_ok=True)
    update(d / STATUS, id=diagnosis_id, analysis_id=analysis_id, status="queued", progress=0.0, stage="queued",
           attempts=1, options={"candidates": list(options.candidates), "seed": options.seed, "model": options.model},
           vehicle={"name": rec.vehicle_name, "version": rec.vehicle_version})
    _worker(request.app).submit(d / STATUS, _diagnosis_work(store, d))
    return _read(d)


def _read(d: Path) -> dict[str, Any]:
    doc = state(d / STATUS) or {}
    if doc.get("status") in ACTIVE and time.time() - doc.get("updated_at", 0) > 3600:
        doc["status"], doc["error"] = "failed", {"code": "interrupted", "detail": "no progress for an hour"}
    doc.pop("owner", None)
    doc.pop("worker_pid", None)
    report = d / "report.json"
    if report.is_file():
        doc["report"] = json.loads(report.read_text(encoding="utf-8"))
    validation = state(d / VALIDATION)
    if validation is not None:
        validation.pop("owner", None)
        validation.pop("worker_pid", None)
        doc["validation"] = validation
    doc["plots"] = [k for k, f in PLOTS.items() if (d / f).is_file()]
    return doc


@router.get("/diagnoses/{diagnosis_id}", response_model=DiagnosisOut,
            summary="Status, progress and (when done) the diagnosis report")
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


@router.post("/diagnoses/{diagnosis_id}/apply", status_code=status.HTTP_201_CREATED, response_model=AppliedOut,
             summary="Apply the diagnosed effect: store a new vehicle version (the augmented model)")
def apply_diagnosis(diagnosis_id: str, body: ApplyBody, store: StoreDep) -> dict[str, Any]:
    from app.pipeline import check_vehicle_files
    from sim import dump_toml, load_vehicle
    from sim.effects import apply_effects

    d = _dir(store, diagnosis_id)
    report = _done_report(d, diagnosis_id)
    st = json.loads((d / STATUS).read_text(encoding="utf-8"))
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
    update(d / STATUS, applied={"vehicle": rec.name, "version": rec.version, "effects": effects})
    return {"vehicle": rec.name, "version": rec.version, "created": created, "effects": effects,
            "from": f"{veh.name}@{veh.version}"}


def _validation_work(store: Store, d: Path) -> Work:
    """The validation ``d/validation.json`` describes (the other log) of the diagnosis in ``d``, as work."""
    report = json.loads((d / "report.json").read_text(encoding="utf-8"))
    _chosen(report)
    _options(report["options"], report["model"])  # unreadable now, not in the worker
    if "log_id" not in json.loads((d / VALIDATION).read_text(encoding="utf-8")):
        raise KeyError(f"{d / VALIDATION} names no log_id")
    return partial(_run_validation, store.url, str(d))


def _run_validation(root: str, dir_: str, check: Check) -> None:
    """Worker-process side of a validation: decode the other log, measure the shrink, write ``validation.json``."""
    from app.analysis.diagnosis import validate_effects

    d = Path(dir_)
    path = d / VALIDATION
    report = json.loads((d / "report.json").read_text(encoding="utf-8"))
    effects = _chosen(report)
    options = _options(report["options"], report["model"])
    st = json.loads((d / STATUS).read_text(encoding="utf-8"))
    log_id = json.loads(path.read_text(encoding="utf-8"))["log_id"]

    def run(store: Store) -> None:
        update(path, status="running")
        signals, vehicle = _decode(store, log_id, st["vehicle"]["name"], st["vehicle"]["version"])
        val = validate_effects(effects, signals, vehicle, options, lambda fraction, message: check())
        write_json(path, {"status": "done", "log_id": log_id, **val.to_dict()})

    _in_store(root, run)


@router.post("/diagnoses/{diagnosis_id}/validate", status_code=status.HTTP_202_ACCEPTED, response_model=DiagnosisOut,
             summary="Validate the diagnosed effect on another log (runs in the background)")
def validate_diagnosis(diagnosis_id: str, body: ValidateBody, store: StoreDep, request: Request) -> dict[str, Any]:
    d = _dir(store, diagnosis_id)
    _chosen(_done_report(d, diagnosis_id))  # 409 / 422 now rather than in the background
    store.get_log(body.log_id)  # 404 now rather than in the background
    write_json(d / VALIDATION, {"status": "queued", "log_id": body.log_id, "attempts": 1})
    _worker(request.app).submit(d / VALIDATION, _validation_work(store, d))
    return _read(d)
