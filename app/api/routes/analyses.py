"""Analyses: log x vehicle -> events, simulation, metrics; run in the background, results kept."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Query, Response, status
from fastapi.responses import JSONResponse, PlainTextResponse

from app.analysis.metrics import METRIC_NAMES
from app.analysis.tolerance import MAX_SAMPLES
from app.api.deps import ResultsDep, RunnerDep, SettingsDep, StoreDep
from app.api.schemas import (
    ERRORS,
    AnalysisCreate,
    AnalysisOut,
    ErrorOut,
    EventsOut,
    JobStateOut,
    MetricsOut,
    ToleranceOut,
    job_timing,
    unit_of,
)
from app.api.tables import events_csv, metrics_csv
from app.errors import AppError, ConflictError, NotFoundError, QueueFullError
from app.jobkinds import tolerance_subject
from app.jobs import JobRunner
from app.pipeline import AnalysisOptions
from app.storage.base import Store
from app.storage.records import AnalysisRecord, JobRecord, JobStatus
from app.storage.results import ResultCache, ResultFiles

router = APIRouter(prefix="/analyses", tags=["analyses"], responses=ERRORS)
JOB_ERROR_STATUS = {"internal_error": 500, "storage_error": 500, "worker_died": 500, "storage_full": 507}

#: Called with the id of every deleted analysis (e.g. the series routes drop their cached answers).
ON_DELETE: list[Callable[[str], None]] = []


def deleted(analysis_ids: list[str]) -> None:
    for analysis_id in analysis_ids:
        for forget in ON_DELETE:
            forget(analysis_id)


def room_for_a_job(store: Store, limit: int) -> None:
    """429 ``queue_full`` while ``limit`` jobs wait: a burst of requests cannot bury new work for minutes."""
    queued = store.job_counts().get(JobStatus.QUEUED.value, 0)
    if queued >= limit:
        raise QueueFullError(f"{queued} jobs are waiting (limit {limit}, LASHSCOPE_MAX_QUEUED_JOBS); "
                             "try again when some have finished")
TableFormat = Annotated[Literal["json", "csv"] | None, Query(alias="format", description="csv: one row per event")]
CSV_DOC: dict[int | str, dict[str, Any]] = {200: {"content": {"text/csv": {}}}}


def finished(store: Store, cache: ResultCache, analysis_id: str) -> tuple[AnalysisRecord, ResultFiles]:
    """The record and result files of a finished analysis; typed errors otherwise.

    A failed analysis answers with its own error (e.g. 422 ``missing_signal``); one still
    queued or running answers 409 ``analysis_not_ready``.
    """
    rec = store.get_analysis(analysis_id)
    job = rec.job
    if job.status is JobStatus.FAILED:
        err = AppError(f"analysis {analysis_id} failed: {job.error_detail}", code=job.error_code or "analysis_failed")
        err.status = JOB_ERROR_STATUS.get(job.error_code or "", 422)
        raise err
    if job.status is not JobStatus.DONE:
        raise ConflictError(f"analysis {analysis_id} is {job.status.value} ({job.stage}, {job.progress:.0%})",
                            code="analysis_not_ready")
    return rec, cache.get(rec.result_dir)


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=AnalysisOut,
             summary="Start an analysis of a log with a vehicle (runs in the background)")
def create_analysis(body: AnalysisCreate, store: StoreDep, runner: RunnerDep, settings: SettingsDep) -> AnalysisOut:
    opts = AnalysisOptions.from_dict(body.options)  # 400 on bad options, before anything is queued
    room_for_a_job(store, settings.max_queued_jobs)
    store.get_log(body.log_id)
    vehicle = store.get_vehicle(body.vehicle, body.vehicle_version)
    rec = store.create_analysis(body.log_id, vehicle, opts.to_dict())
    runner.submit(rec.job.id)
    return AnalysisOut.of(store.get_analysis(rec.id))


@router.get("", response_model=list[AnalysisOut], summary="List analyses, newest first")
def list_analyses(store: StoreDep, log_id: str | None = None, limit: Annotated[int, Query(ge=1, le=1000)] = 100,
                  offset: Annotated[int, Query(ge=0, le=2**62)] = 0) -> list[AnalysisOut]:
    return [AnalysisOut.of(a) for a in store.list_analyses(log_id, limit, offset)]


@router.get("/{analysis_id}", response_model=AnalysisOut, summary="Status, progress and summary")
async def get_analysis(analysis_id: str, store: StoreDep) -> AnalysisOut:
    # async: one SQLite row read, cheaper on the event loop than a thread hop on a loaded machine (the
    # dashboard polls it, and reads it beside the chart's rows on the analysis view's first paint)
    return AnalysisOut.of(store.get_analysis(analysis_id))


@router.delete("/{analysis_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete an analysis; its running or queued jobs are cancelled")
def delete_analysis(analysis_id: str, store: StoreDep, cache: ResultsDep, runner: RunnerDep) -> Response:
    rec = store.get_analysis(analysis_id)
    cancel_jobs(store, runner, analysis_id)
    store.delete_analysis(analysis_id)
    cache.forget(rec.result_dir)
    deleted([analysis_id])
    return Response(status_code=status.HTTP_204_NO_CONTENT)


def cancel_jobs(store: Store, runner: JobRunner, analysis_id: str) -> None:
    """Cancel the analysis' own job and its tolerance bands, queued or running."""
    for job in store.active_jobs(analysis_id):
        runner.cancel(job.id, f"cancelled: analysis {analysis_id} was deleted")


@router.get("/{analysis_id}/events", response_model=EventsOut, responses=CSV_DOC,
            summary="Tip-in/tip-out events, excluded ones with the reason")
def get_events(analysis_id: str, store: StoreDep, cache: ResultsDep,
               included: bool | None = None, fmt: TableFormat = None) -> Any:
    _, files = finished(store, cache, analysis_id)
    events = files.doc["events"]
    if included is not None:
        events = [e for e in events if e["included"] is included]
    if fmt == "csv":
        return PlainTextResponse(events_csv(events), media_type="text/csv")
    return {"analysis_id": analysis_id, "count": len(events), "events": events}


@router.get("/{analysis_id}/metrics", response_model=MetricsOut, responses=CSV_DOC,
            summary="Ripple metrics per event: measured, simulated, differences")
def get_metrics(analysis_id: str, store: StoreDep, cache: ResultsDep, fmt: TableFormat = None) -> Any:
    _, files = finished(store, cache, analysis_id)
    d = files.doc
    if fmt == "csv":
        return PlainTextResponse(metrics_csv(d["metrics"]), media_type="text/csv")
    return {"analysis_id": analysis_id, "summary": d["summary"], "offset": d["offset"], "whole": d["whole"],
            "events": d["metrics"], "notes": d["notes"], "tracking": d.get("tracking"),
            "sampling": d.get("sampling"),  # absent from results stored before they existed
            "units": {n: unit_of(n) for n in METRIC_NAMES}}


TolN = Annotated[int, Query(ge=1, le=MAX_SAMPLES, description="Monte Carlo variants per event")]
TolSeed = Annotated[int, Query(ge=0, le=2**32 - 1, description="random seed of the sampling")]


@router.get("/{analysis_id}/tolerance", summary="Predicted ripple band over the vehicle's tolerances",
            responses={200: {"model": ToleranceOut},
                       202: {"description": "computing: the job's status and progress"},
                       404: {"description": "not computed: POST to start it"}})
def get_tolerance(analysis_id: str, store: StoreDep, cache: ResultsDep, n: TolN = 200, seed: TolSeed = 0) -> Response:
    """Per analysed event: the 5/50/95 % band of the predicted peak-to-valley fluctuation with every
    gap and ``vehicle.tolerances`` band sampled uniformly, the nominal vehicle's value, the measured
    value and its percentile in the predicted distribution.

    Reading never starts work: 200 with the band once computed, 202 with the job's progress while
    it runs, 404 ``tolerance_not_started`` before ``POST`` started it, or the job's error.
    """
    finished(store, cache, analysis_id)
    band = store.artifacts.get("tolerance", tolerance_subject(analysis_id, n, seed), "band")
    if band is not None:
        return JSONResponse(band)
    job = store.find_job("tolerance", tolerance_subject(analysis_id, n, seed))
    if job is None or job.status is JobStatus.DONE:  # never started, or its result was removed
        raise NotFoundError(f"no tolerance band n={n} seed={seed} for {analysis_id}; start it with POST "
                            f"/analyses/{analysis_id}/tolerance?n={n}&seed={seed}", code="tolerance_not_started")
    _raise_failed(analysis_id, job)
    return _accepted(analysis_id, n, seed, job)


@router.post("/{analysis_id}/tolerance", status_code=status.HTTP_202_ACCEPTED,
             summary="Start computing the tolerance band (background job)",
             responses={200: {"model": ToleranceOut, "description": "already computed: the band"}})
def start_tolerance(analysis_id: str, store: StoreDep, cache: ResultsDep, runner: RunnerDep, settings: SettingsDep,
                    n: TolN = 200, seed: TolSeed = 0) -> Response:
    """Starts the job unless the band exists (200 with it) or its job is queued or running (202 with that
    job); a failed job is started again. Poll ``GET`` with the same ``n`` and ``seed``."""
    finished(store, cache, analysis_id)
    subject = tolerance_subject(analysis_id, n, seed)
    band = store.artifacts.get("tolerance", subject, "band")
    if band is not None:
        return JSONResponse(band)
    job = store.find_job("tolerance", subject)
    if job is None or job.status in (JobStatus.FAILED, JobStatus.DONE):
        room_for_a_job(store, settings.max_queued_jobs)
        job = store.create_job("tolerance", subject)
        runner.submit(job.id)
    return _accepted(analysis_id, n, seed, job)


@router.get("/{analysis_id}/tolerance/status", response_model=JobStateOut,
            summary="Whether the tolerance band is computed, computing (with progress) or not started")
def tolerance_status(analysis_id: str, store: StoreDep, cache: ResultsDep, n: TolN = 200,
                     seed: TolSeed = 0) -> JobStateOut:
    finished(store, cache, analysis_id)
    if store.artifacts.has("tolerance", tolerance_subject(analysis_id, n, seed), "band"):
        return JobStateOut(status="done", progress=1.0)
    return job_state(store.find_job("tolerance", tolerance_subject(analysis_id, n, seed)))


def job_state(job: JobRecord | None) -> JobStateOut:
    """A result's job as a state; ``not_started`` without a job, or when its job is done but the result
    is gone (the caller checked the result first)."""
    if job is None or job.status is JobStatus.DONE:
        return JobStateOut(status="not_started")
    err = ErrorOut(code=job.error_code or "job_failed", detail=job.error_detail or "") \
        if job.status is JobStatus.FAILED else None
    return JobStateOut(status=job.status.value, progress=job.progress, stage=job.stage, job_id=job.id, error=err,
                       **job_timing(job))


def _raise_failed(analysis_id: str, job: JobRecord) -> None:
    if job.status is JobStatus.FAILED:
        err = AppError(f"tolerance band of {analysis_id} failed: {job.error_detail}",
                       code=job.error_code or "tolerance_failed")
        err.status = JOB_ERROR_STATUS.get(job.error_code or "", 422)
        raise err


def _accepted(analysis_id: str, n: int, seed: int, job: JobRecord) -> JSONResponse:
    return JSONResponse(status_code=status.HTTP_202_ACCEPTED, content={
        "analysis_id": analysis_id, "n": n, "seed": seed, "job_id": job.id, "status": job.status.value,
        "stage": job.stage, "progress": job.progress})
