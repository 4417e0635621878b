"""Identifications: a vehicle's base parameters learnt from its own stored logs (``lashscope identify``).

::

    POST   /identifications                 {"log_ids": [...], "vehicle": "ev", "validate_log_ids": [...]} -> 202
    GET    /identifications/{id}            status, progress; the result when done (parameters with intervals,
                                            the model-free mode, the withheld drives' tracking before and after)
    GET    /identifications/{id}/vehicle    the identified vehicle file (TOML, with its [provenance])
    POST   /identifications/{id}/apply      store it as a new version of the vehicle -> 201
    DELETE /identifications/{id}            cancel it if it runs, and remove it

An identification is one job of the job runner (kind :mod:`app.jobkinds.identification`, the long
lane, ``LASHSCOPE_DIAGNOSIS_TIMEOUT_S``). Logs are named by id and file name; the store's paths never
leave the server.
"""

from __future__ import annotations

import uuid
from typing import Any

from fastapi import APIRouter, Response, status

from app.api.deps import RunnerDep, SettingsDep, StoreDep
from app.api.routes.analyses import room_for_a_job
from app.api.schemas import (
    ERRORS,
    AppliedOut,
    IdentificationCreate,
    IdentificationOut,
    IdentificationResultOut,
    JobOut,
)
from app.errors import ConflictError, InputError, NotFoundError
from app.identify import BASE_NAMES
from app.pipeline import check_vehicle_files
from app.storage.base import Store
from app.storage.records import JobRecord, JobStatus

router = APIRouter(prefix="/identifications", tags=["identifications"], responses=ERRORS)
PREFIX = "id_"
KIND = "identification"  # the artefact kind (app.storage.artifacts)


def _load(store: Store, identification_id: str) -> tuple[dict[str, Any], JobRecord]:
    ok = (identification_id.startswith(PREFIX) and identification_id[len(PREFIX):].isalnum()
          and len(identification_id) <= 64)  # longer ones are not ours (and past NAME_MAX)
    req = store.artifacts.get(KIND, identification_id, "request") if ok else None
    job = store.find_job("identification", identification_id) if req is not None else None
    if req is None or job is None:
        raise NotFoundError(f"identification {identification_id!r} not found", code="identification_not_found")
    return req, job


def _out(store: Store, identification_id: str, req: dict[str, Any], job: JobRecord) -> IdentificationOut:
    result = store.artifacts.get(KIND, identification_id, "result") if job.status is JobStatus.DONE else None
    base = f"/identifications/{identification_id}"
    links = {"self": base}
    if result is not None:
        links.update(vehicle=f"{base}/vehicle", apply=f"{base}/apply")
    return IdentificationOut(id=identification_id, status=job.status.value, progress=job.progress, stage=job.stage,
                             job=JobOut.of(job), vehicle=req["vehicle"], vehicle_version=req["vehicle_version"],
                             log_ids=req["log_ids"], validate_log_ids=req["validate_log_ids"], params=req["params"],
                             result=IdentificationResultOut.model_validate(result) if result else None,
                             applied=req.get("applied"), links=links)


@router.post("", status_code=status.HTTP_202_ACCEPTED, response_model=IdentificationOut,
             summary="Identify a vehicle's base parameters from uploaded logs (a background job)")
def create_identification(body: IdentificationCreate, store: StoreDep, runner: RunnerDep,
                          settings: SettingsDep) -> IdentificationOut:
    every = [*body.log_ids, *body.validate_log_ids]
    if len(set(every)) != len(every):
        raise InputError("log_ids and validate_log_ids name a log more than once (a withheld drive must not be "
                         "fitted)")
    unknown = [p for p in body.params if p not in BASE_NAMES]
    if unknown or len(set(body.params)) != len(body.params):
        raise InputError(f"params {body.params}: base parameters are {', '.join(BASE_NAMES)}, each at most once")
    for log_id in every:  # 404 now rather than in the background
        store.get_log(log_id)
    vehicle = store.get_vehicle(body.vehicle, body.vehicle_version)
    room_for_a_job(store, settings.max_queued_jobs)
    identification_id = f"{PREFIX}{uuid.uuid4().hex[:16]}"
    req = {"log_ids": body.log_ids, "validate_log_ids": body.validate_log_ids, "vehicle": vehicle.name,
           "vehicle_version": vehicle.version, "params": list(body.params or BASE_NAMES), "seed": body.seed,
           "name": vehicle.name}
    store.artifacts.put(KIND, identification_id, "request", req)
    job = store.create_job("identification", identification_id)
    runner.submit(job.id)
    return _out(store, identification_id, req, job)


@router.get("/{identification_id}", response_model=IdentificationOut,
            summary="Status and progress of an identification; its result when done")
def get_identification(identification_id: str, store: StoreDep) -> IdentificationOut:
    req, job = _load(store, identification_id)
    return _out(store, identification_id, req, job)


def _done(store: Store, identification_id: str) -> tuple[dict[str, Any], JobRecord]:
    req, job = _load(store, identification_id)
    if job.status is not JobStatus.DONE or store.artifacts.file(KIND, identification_id, "vehicle") is None:
        raise ConflictError(f"identification {identification_id} is {job.status.value}",
                            code="identification_not_ready")
    return req, job


@router.get("/{identification_id}/vehicle", summary="The identified vehicle file (TOML with its provenance)",
            response_class=Response, responses={200: {"content": {"application/toml": {}}}})
def identified_vehicle(identification_id: str, store: StoreDep) -> Response:
    _done(store, identification_id)
    path = store.artifacts.file(KIND, identification_id, "vehicle")
    if path is None:  # removed since _done looked
        raise NotFoundError(f"identification {identification_id!r} not found", code="identification_not_found")
    text = path.read_text(encoding="utf-8")
    return Response(text, media_type="application/toml")


@router.post("/{identification_id}/apply", status_code=status.HTTP_201_CREATED, response_model=AppliedOut,
             summary="Store the identified vehicle as a new version of the vehicle")
def apply_identification(identification_id: str, store: StoreDep) -> dict[str, Any]:
    req, _ = _done(store, identification_id)
    identified = store.artifacts.file(KIND, identification_id, "vehicle")
    if identified is None:  # removed since _done looked
        raise NotFoundError(f"identification {identification_id!r} not found", code="identification_not_found")
    veh = store.get_vehicle(req["vehicle"], req["vehicle_version"])
    summary = check_vehicle_files(identified, veh.database_path, veh.signal_map_path)
    result = store.artifacts.get(KIND, identification_id, "result") or {}
    summary["identification"] = {"id": identification_id, "from": f"{veh.name}@{veh.version}",
                                 "named": result.get("named", [])}
    rec, created = store.add_vehicle(veh.name, driveline=identified, database=veh.database_path,
                                     signal_map=veh.signal_map_path, summary=summary)
    store.artifacts.put(KIND, identification_id, "request",
                        {**req, "applied": {"vehicle": rec.name, "version": rec.version}})
    return {"vehicle": rec.name, "version": rec.version, "created": created, "effects": {},
            "from": f"{veh.name}@{veh.version}"}


@router.delete("/{identification_id}", status_code=status.HTTP_204_NO_CONTENT,
               summary="Delete an identification: its job is cancelled if it runs, its files removed")
def delete_identification(identification_id: str, store: StoreDep, runner: RunnerDep) -> Response:
    _, job = _load(store, identification_id)
    if job.status in (JobStatus.QUEUED, JobStatus.RUNNING):
        runner.cancel(job.id, f"cancelled: identification {identification_id} was deleted")
    store.artifacts.delete(KIND, identification_id)
    return Response(status_code=status.HTTP_204_NO_CONTENT)
