"""Diagnoses: which unmodelled effect explains an analysis' sim-to-real gap, and does it hold elsewhere.

::

    POST /analyses/{analysis_id}/diagnoses   {"candidates": [...], "seed": 0, "model": "multibody"}  -> 202
    GET  /diagnoses/{diagnosis_id}           status and progress; the report (lashscope.diagnosis/1) when done
    GET  /diagnoses/{diagnosis_id}/plots/{events|residual}   PNG
    GET  /diagnoses/{diagnosis_id}/charts    the plots' numbers as JSON (the dashboard draws them)
    POST /diagnoses/{diagnosis_id}/apply     {"name": optional}  -> 201 new vehicle version with the effect
    POST /diagnoses/{diagnosis_id}/validate  {"log_id": ...}     -> 202; shrink on that drive in the report

Diagnoses and validations are jobs of the one job runner (:mod:`app.jobs`; kinds
:mod:`app.jobkinds.diagnosis` and :mod:`app.jobkinds.validation`): each runs in its own spawned
worker process under a lease, killed after ``LASHSCOPE_DIAGNOSIS_TIMEOUT_S`` (the diagnosis then
fails with code ``timeout``), resumed once after a crash and never run twice at once, and
cancelled with its analysis. Status, progress, attempts and errors come from the job row; the
diagnosis artefact of the store (``store.artifacts``, :mod:`app.storage.artifacts`: its status,
report, charts, validation and PNG plots) holds what was asked and what came out.
"""

from __future__ import annotations

import secrets
from typing import Any

from fastapi import APIRouter, status
from fastapi.responses import FileResponse
from pydantic import BaseModel, Field

from app.api.deps import RunnerDep, SettingsDep, StoreDep
from app.api.routes.analyses import room_for_a_job
from app.api.schemas import ERRORS, AppliedOut, DiagnosisChartsOut, DiagnosisOut, job_timing
from app.diagnosis_decision import base_ratios, chosen
from app.errors import ConflictError, NotFoundError
from app.identify.base import with_base
from app.jobkinds import DIAGNOSIS_SEP, diagnosis_subject, validation_subject
from app.pipeline import check_vehicle_files
from app.storage.base import Store
from app.storage.records import JobStatus
from app.storage.sqlstore import check_vehicle_name
from sim import dump_toml, load_vehicle
from sim.effects import EFFECTS, apply_effects


class DiagnosisCreate(BaseModel):
    candidates: list[str] | None = Field(default=None, description="effect ids; default: the whole library")
    seed: int = Field(default=0, ge=0, le=2**31 - 1, description="seed of the calibration/held-out split")
    model: str = Field(default="multibody", description="simulator model: multibody or two_inertia")


class ApplyBody(BaseModel):
    name: str | None = Field(default=None, description="vehicle name for the new version (default: the analysed one)")


class ValidateBody(BaseModel):
    log_id: str


router = APIRouter(tags=["diagnoses"], responses=ERRORS)
ACTIVE = (JobStatus.QUEUED, JobStatus.RUNNING)
KIND = "diagnosis"  # the artefact kind (app.storage.artifacts)
PLOTS = {"events": "plot_events", "residual": "plot_residual"}  # plot name -> the artefact's file part


def _known(store: Store, diagnosis_id: str) -> str:
    if not store.artifacts.has(KIND, diagnosis_id, "status"):  # also every id that cannot name one
        raise NotFoundError(f"diagnosis {diagnosis_id!r} not found", code="diagnosis_not_found")
    return diagnosis_id


def _job_state(store: Store, doc: dict[str, Any]) -> dict[str, Any]:
    """``doc`` (a status or validation file) with its job's status, progress, stage, attempts and error.

    Files written before diagnoses ran as jobs carry their own status; one left queued or running
    by that runner is reported failed (``interrupted``): nothing runs it any more.
    """
    doc = {k: v for k, v in doc.items() if k not in ("owner", "worker_pid", "updated_at")}
    job_id = doc.get("job_id")
    if job_id is None:
        if doc.get("status") in ("queued", "running"):
            doc.update(status="failed", error={"code": "interrupted", "detail": "interrupted by an upgrade of the "
                                                "server; start it again"})
        return doc
    try:
        job = store.get_job(job_id)
    except NotFoundError:
        return {**doc, "status": "failed", "error": {"code": "interrupted", "detail": "its job is gone"}}
    doc.update(status=job.status.value, progress=job.progress, stage=job.stage, attempts=job.attempts,
               **job_timing(job))
    if job.status is JobStatus.FAILED:
        doc["error"] = {"code": job.error_code, "detail": job.error_detail}
    return doc


def _read(store: Store, diagnosis_id: str) -> dict[str, Any]:
    art = store.artifacts
    doc = _job_state(store, art.get(KIND, diagnosis_id, "status") or {})
    report = art.get(KIND, diagnosis_id, "report")
    if report is not None and doc.get("status") == "done":
        doc["report"] = report
    val = art.get(KIND, diagnosis_id, "validation")
    if val is not None:
        doc["validation"] = _job_state(store, val)
    doc["plots"] = [k for k, part in PLOTS.items() if art.has(KIND, diagnosis_id, part)]
    return doc


@router.post("/analyses/{analysis_id}/diagnoses", status_code=status.HTTP_202_ACCEPTED, response_model=DiagnosisOut,
             summary="Start a diagnosis of an analysis' sim-to-real gap (runs in the background)")
def create_diagnosis(analysis_id: str, body: DiagnosisCreate, store: StoreDep, runner: RunnerDep,
                     settings: SettingsDep) -> dict[str, Any]:
    from app.analysis.diagnosis import DiagnosisOptions  # lazy: the diagnosis library loads on first use

    rec = store.get_analysis(analysis_id)
    options = DiagnosisOptions(candidates=tuple(body.candidates) if body.candidates else tuple(EFFECTS),
                               seed=body.seed, model=body.model)  # 400 on unknown candidates or model
    room_for_a_job(store, settings.max_queued_jobs)
    diagnosis_id = f"{analysis_id}{DIAGNOSIS_SEP}{secrets.token_hex(4)}"
    job = store.create_job("diagnosis", diagnosis_subject(analysis_id, diagnosis_id))
    store.artifacts.put(KIND, diagnosis_id, "status", {
        "id": diagnosis_id, "analysis_id": analysis_id, "job_id": job.id,
        "options": {"candidates": list(options.candidates), "seed": options.seed, "model": options.model},
        "vehicle": {"name": rec.vehicle_name, "version": rec.vehicle_version}})
    runner.submit(job.id)
    return _read(store, diagnosis_id)


@router.get("/diagnoses/{diagnosis_id}", response_model=DiagnosisOut,
            summary="Status, progress and (when done) the diagnosis report")
def get_diagnosis(diagnosis_id: str, store: StoreDep) -> dict[str, Any]:
    return _read(store, _known(store, diagnosis_id))


@router.get("/diagnoses/{diagnosis_id}/plots/{name}", summary="Per-event overlay or residual chart (PNG)",
            response_class=FileResponse)
def get_plot(diagnosis_id: str, name: str, store: StoreDep) -> FileResponse:
    _known(store, diagnosis_id)
    if name not in PLOTS:
        raise NotFoundError(f"plot {name!r}: use one of {sorted(PLOTS)}", code="plot_not_found")
    path = store.artifacts.file(KIND, diagnosis_id, PLOTS[name])
    if path is None:
        raise ConflictError(f"diagnosis {diagnosis_id} has no {name} plot yet", code="diagnosis_not_ready")
    return FileResponse(path, media_type="image/png")


@router.get("/diagnoses/{diagnosis_id}/charts", response_model=DiagnosisChartsOut,
            summary="The numbers behind the diagnosis plots: held-out residual by event, phase and band before "
                    "and after the chosen fit; measured, baseline and fitted speed of held-out events")
def get_charts(diagnosis_id: str, store: StoreDep) -> dict[str, Any]:
    _known(store, diagnosis_id)
    doc = store.artifacts.get(KIND, diagnosis_id, "charts")
    if doc is not None:
        return doc
    state = _read(store, diagnosis_id)
    if state.get("status") != "done":
        raise ConflictError(f"diagnosis {diagnosis_id} is {state.get('status')}: no charts yet",
                            code="diagnosis_not_ready")
    report = state.get("report") or {}
    decision = report.get("decision") or {}
    if report.get("baseline") is None:
        raise NotFoundError(f"diagnosis {diagnosis_id} has no charts: it decided {decision.get('status')!r} "
                            "without a calibrated baseline", code="charts_not_found")
    raise NotFoundError(f"diagnosis {diagnosis_id} was made before its chart numbers were kept; run it again "
                        "(its PNG plots are at /plots/events and /plots/residual)", code="charts_not_found")


def _done_report(store: Store, diagnosis_id: str) -> dict[str, Any]:
    doc = _read(store, diagnosis_id)
    if doc.get("status") != "done" or "report" not in doc:
        raise ConflictError(f"diagnosis {diagnosis_id} is {doc.get('status')}", code="diagnosis_not_ready")
    report: dict[str, Any] = doc["report"]
    return report


@router.post("/diagnoses/{diagnosis_id}/apply", status_code=status.HTTP_201_CREATED, response_model=AppliedOut,
             summary="Apply the diagnosed effect: store a new vehicle version (the augmented model)")
def apply_diagnosis(diagnosis_id: str, body: ApplyBody, store: StoreDep) -> dict[str, Any]:
    if body.name is not None:
        check_vehicle_name(body.name)  # before anything is read or written: the name never reaches a path
    report = _done_report(store, _known(store, diagnosis_id))
    st = store.artifacts.get(KIND, diagnosis_id, "status") or {}
    veh = store.get_vehicle(st["vehicle"]["name"], st["vehicle"]["version"])
    effects = chosen(report)
    augmented = apply_effects(with_base(load_vehicle(veh.driveline_path), base_ratios(report)), effects)
    name = body.name or veh.name
    path = store.temp_path(".toml")  # the store keeps its own copy; this one goes either way
    try:
        path.write_text(dump_toml(augmented), encoding="utf-8")
        summary = check_vehicle_files(path, veh.database_path, veh.signal_map_path)
        summary["diagnosis"] = {"id": diagnosis_id, "effects": effects, "from": f"{veh.name}@{veh.version}"}
        rec, created = store.add_vehicle(name, driveline=path, database=veh.database_path,
                                         signal_map=veh.signal_map_path, summary=summary)
    finally:
        path.unlink(missing_ok=True)
    store.artifacts.update(KIND, diagnosis_id, "status",
                           applied={"vehicle": rec.name, "version": rec.version, "effects": effects})
    return {"vehicle": rec.name, "version": rec.version, "created": created, "effects": effects,
            "from": f"{veh.name}@{veh.version}"}


@router.post("/diagnoses/{diagnosis_id}/validate", status_code=status.HTTP_202_ACCEPTED, response_model=DiagnosisOut,
             summary="Validate the diagnosed effect on another log (runs in the background)")
def validate_diagnosis(diagnosis_id: str, body: ValidateBody, store: StoreDep, runner: RunnerDep,
                       settings: SettingsDep) -> dict[str, Any]:
    chosen(_done_report(store, _known(store, diagnosis_id)))  # 409 / 422 now rather than in the background
    store.get_log(body.log_id)  # 404 now rather than in the background
    earlier = store.artifacts.get(KIND, diagnosis_id, "validation")
    if earlier and earlier.get("job_id") and store.get_job(earlier["job_id"]).status in ACTIVE:
        raise ConflictError(f"diagnosis {diagnosis_id} is being validated already (job {earlier['job_id']})",
                            code="validation_busy")
    room_for_a_job(store, settings.max_queued_jobs)
    analysis_id = diagnosis_id.rsplit(DIAGNOSIS_SEP, 1)[0]
    job = store.create_job("validation", validation_subject(analysis_id, diagnosis_id))
    store.artifacts.put(KIND, diagnosis_id, "validation", {"log_id": body.log_id, "job_id": job.id})
    runner.submit(job.id)
    return _read(store, diagnosis_id)
