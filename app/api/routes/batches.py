"""Batches: the fleet batch pipeline (``lashscope batch``, docs/fleet.md) over logs already uploaded.

::

    POST   /batches                {"log_ids": [...], "vehicle": "ev", "options": {...}}  -> 202 BatchOut
    GET    /batches/{batch_id}     status, progress, counts; the summary when done
    GET    /batches/{batch_id}/logs   one row per log: ok (events, summary, tracking) | failed (code) | pending
    DELETE /batches/{batch_id}     cancel it if it runs, and remove its output

A batch is one job of the job runner (kind :mod:`app.jobkinds.batch`): one worker process under
a lease and ``LASHSCOPE_BATCH_TIMEOUT_S``, resumed after a crash where it stopped. Logs are named
by id and file name only; the store's internal paths never leave the server.
"""

from __future__ import annotations

import json
import uuid
from typing import Any

from fastapi import APIRouter, Response, status

from app.api.deps import RunnerDep, SettingsDep, StoreDep
from app.api.routes.analyses import room_for_a_job
from app.api.schemas import ERRORS, BatchCreate, BatchLogsOut, BatchOut, JobOut
from app.errors import InputError, NotFoundError
from app.fleet.batch import read_records
from app.pipeline import AnalysisOptions
from app.storage.base import Store
from app.storage.records import JobRecord, JobStatus

router = APIRouter(prefix="/batches", tags=["batches"], responses=ERRORS)
KIND = "batch"  # the artefact kind (app.storage.artifacts)


def _load(store: Store, batch_id: str) -> tuple[dict[str, Any], JobRecord]:
    ok = batch_id.startswith("ba_") and batch_id[3:].isalnum() and len(batch_id) <= 64  # longer ones are not ours
    req = store.artifacts.get(KIND, batch_id, "request") if ok else None
    job = store.find_job("batch", batch_id) if req is not None else None
    if req is None or job is None:
        raise NotFoundError(f"batch {batch_id!r} not found", code="batch_not_found")
    return req, job


def _rows(store: Store, batch_id: str, req: dict[str, Any]) -> list[dict[str, Any]]:
    found = read_records(store.artifacts.workdir(KIND, batch_id))
    rows = []
    by_name = {str(r.get("log_name")): r for r in found.values()}  # a log that could not be read at all
    for log_id, filename, sha, stored in zip(req["log_ids"], req["filenames"], req["hashes"], req["stored"],
                                             strict=True):
        rec = found.get(sha) or by_name.get(stored)
        if rec is None:
            rows.append({"log_id": log_id, "filename": filename, "status": "pending"})
            continue
        row = {k: v for k, v in rec.items() if k not in ("log", "log_name", "format")}
        if "message" in row:  # a failure names the stored file; the user knows it by its upload name
            for internal in (str(rec.get("log", "")), str(rec.get("log_name", ""))):
                row["message"] = str(row["message"]).replace(internal, filename) if internal else row["message"]
        rows.append({**row, "log_id": log_id, "filename": filename})
    return rows


def _out(store: Store, batch_id: str, req: dict[str, Any], job: JobRecord) -> BatchOut:
    counts = {"ok": 0, "failed": 0, "pending": 0}
    for row in _rows(store, batch_id, req):
        counts[row["status"] if row["status"] in counts else "failed"] += 1
    summary = store.artifacts.get(KIND, batch_id, "summary") if job.status is JobStatus.DONE else None
    base = f"/batches/{batch_id}"
    return BatchOut(id=batch_id, status=job.status.value, progress=job.progress, stage=job.stage, job=JobOut.of(job),
                    vehicle=req["vehicle"], vehicle_version=req["vehicle_version"], vehicle_id=req["vehicle_id"],
                    logs=len(req["log_ids"]), counts=counts, summary=summary,
                    links={"self": base, "logs": f"{base}/logs"})


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=BatchOut,
             summary="Run the fleet batch pipeline over uploaded logs (a background job)")
def create_batch(body: BatchCreate, store: StoreDep, runner: RunnerDep, settings: SettingsDep) -> BatchOut:
    options = AnalysisOptions.from_dict(body.options)  # 400 on bad options, before anything is queued
    if len(set(body.log_ids)) != len(body.log_ids):
        raise InputError("log_ids names a log more than once")
    logs = [store.get_log(log_id) for log_id in body.log_ids]  # 404 now rather than in the background
    vehicle = store.get_vehicle(body.vehicle, body.vehicle_version)
    room_for_a_job(store, settings.max_queued_jobs)
    batch_id = f"ba_{uuid.uuid4().hex[:16]}"
    req = {"log_ids": body.log_ids, "filenames": [rec.filename for rec in logs], "hashes": [rec.sha256 for rec in logs],
           "stored": [rec.path.name for rec in logs],
           "vehicle": vehicle.name, "vehicle_version": vehicle.version, "vehicle_id": body.vehicle_id or vehicle.name,
           "options": options.to_dict(), "diagnose": body.diagnose}
    store.artifacts.put(KIND, batch_id, "request", req)
    job = store.create_job("batch", batch_id)
    runner.submit(job.id)
    return _out(store, batch_id, req, job)


@router.get("/{batch_id}", response_model=BatchOut, summary="Status, progress and counts of a batch")
def get_batch(batch_id: str, store: StoreDep) -> BatchOut:
    req, job = _load(store, batch_id)
    return _out(store, batch_id, req, job)


@router.get("/{batch_id}/logs", response_model=BatchLogsOut, summary="One row per log of a batch")
def get_batch_logs(batch_id: str, store: StoreDep) -> dict[str, Any]:
    req, _ = _load(store, batch_id)
    rows = _rows(store, batch_id, req)
    return {"batch_id": batch_id, "count": len(rows), "logs": json.loads(json.dumps(rows, default=str))}


@router.delete("/{batch_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete a batch: its job is cancelled if it runs, its output removed")
def delete_batch(batch_id: str, store: StoreDep, runner: RunnerDep) -> Response:
    _, job = _load(store, batch_id)
    if job.status in (JobStatus.QUEUED, JobStatus.RUNNING):
        runner.cancel(job.id, f"cancelled: batch {batch_id} was deleted")
    store.artifacts.delete(KIND, batch_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
