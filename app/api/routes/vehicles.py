"""Vehicles: a driveline description (TOML) + DBC + signal map, versioned by name."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse

from app.api.deps import RunnerDep, SettingsDep, StoreDep
from app.api.routes.analyses import JOB_ERROR_STATUS, job_state, room_for_a_job
from app.api.schemas import (
    ERRORS,
    GapSensitivityJobOut,
    GapSensitivityOut,
    JobStateOut,
    SignalMapProposalOut,
    VehicleOut,
)
from app.api.upload import check_toml, receive_upload, user_file_names
from app.bounded import run_bounded
from app.errors import AppError, InputError, NotFoundError, UploadTooLargeError
from app.ingest.signalmap import CANONICAL
from app.jobkinds import gap_sensitivity as gap_job
from app.jobkinds import gap_sensitivity_subject
from app.pipeline import GAP_SENSITIVITY_FORMAT, check_vehicle_files, gap_sensitivity_work
from app.signal_proposal import parse_overrides
from app.storage.base import Store
from app.storage.records import JobRecord, JobStatus
from app.storage.results import json_safe
from app.storage.sqlstore import check_vehicle_name
from sim import dump_toml, load_vehicle, preset_names

router = APIRouter(prefix="/vehicles", tags=["vehicles"], responses=ERRORS)
# bytes each file may have (checked before it is read): a driveline of 24 stages or a signal map is a few kB;
# the largest production DBC we know (Model 3, 148 messages) is 375 KiB and loads in 1.3 s
MAX_FILE_BYTES = {"driveline": 256 * 2**10, "signal_map": 256 * 2**10, "dbc": 4 * 2**20}

FORM_DOC = {
    "requestBody": {
        "content": {"multipart/form-data": {"schema": {"type": "object", "properties": {
            "name": {"type": "string", "description": "vehicle name: a-z, 0-9, '-', '_'"},
            "driveline": {"type": "string", "format": "binary", "description": "driveline TOML (sim format)"},
            "preset": {"type": "string", "description": "instead of a driveline file: a preset name, e.g. paper"},
            "dbc": {"type": "string", "format": "binary", "description": "database (DBC/KCD/SYM/ARXML); "
                    "default: the project's dbc/lashscope_ev.dbc"},
            "signal_map": {"type": "string", "format": "binary",
                           "description": "signal map TOML; default: dbc/lashscope_ev.map.toml"},
        }, "required": ["name"]}}},
        "required": True,
    }
}


@router.post("", status_code=status.HTTP_201_CREATED, response_model=VehicleOut, openapi_extra=FORM_DOC,
             summary="Create a vehicle or a new version of it")
async def create_vehicle(request: Request, response: Response, store: StoreDep, settings: SettingsDep) -> VehicleOut:
    """Every file is checked before anything is stored, within limits set before the work (413
    ``vehicle_file_too_large`` past :data:`MAX_FILE_BYTES`; at most 24 stages; a DBC's limits in
    :mod:`app.ingest.database`): the driveline must load in the simulator and
    pass a cheap trial (one simulated second must need at most 1e6 integrator steps; otherwise 422
    naming the suspect field), the database must load, and the signal map must fit the database.
    Identical content to the latest version returns that version (200, ``unchanged: true``)."""
    up = await receive_upload(request, store.temp_path, max(MAX_FILE_BYTES.values()), 0, urlencoded_form=True,
                              idle_s=settings.upload_idle_s, max_files=len(MAX_FILE_BYTES))
    files = {f.field_name: f.path for f in up.files}
    names = {f.path: f.filename for f in up.files}
    try:
        name = up.fields.get("name", "").strip()
        if not name:
            raise InputError("form field 'name' is required")
        check_vehicle_name(name)
        unknown = set(files) - set(MAX_FILE_BYTES)
        if unknown:
            raise InputError(f"unexpected file fields {sorted(unknown)}; use driveline, dbc, signal_map")
        for f in up.files:
            if f.size > MAX_FILE_BYTES[f.field_name]:
                raise UploadTooLargeError(f"{f.field_name} {f.filename!r} has {f.size} bytes, more than the "
                                          f"{MAX_FILE_BYTES[f.field_name] // 1024} KiB a vehicle's {f.field_name} "
                                          "may have", code="vehicle_file_too_large")
        driveline = files.get("driveline")
        if driveline is None:
            preset = up.fields.get("preset", "").strip()
            if preset not in preset_names():
                raise InputError(f"give a driveline TOML file or a preset; presets: {preset_names()}")
            driveline = store.temp_path(".toml")
            driveline.write_text(_preset_toml(preset), encoding="utf-8")
            names[driveline] = f"preset {preset}"
            files["driveline"] = driveline
        dbc = files.get("dbc") or settings.dbc_dir / "lashscope_ev.dbc"
        smap = files.get("signal_map") or settings.dbc_dir / "lashscope_ev.map.toml"
        for default in {dbc, smap} - set(files.values()):  # the project's own files: named, not located
            names[default] = f"default {default.name}"
        for toml_file in (driveline, smap):
            check_toml(toml_file, names.get(toml_file, toml_file.name))
        with user_file_names(names):
            summary = await run_in_threadpool(check_vehicle_files, driveline, dbc, smap)
        rec, created = await run_in_threadpool(store.add_vehicle, name, driveline=driveline, database=dbc,
                                               signal_map=smap, summary=summary)
    finally:
        for p in files.values():
            p.unlink(missing_ok=True)
    if not created:
        response.status_code = status.HTTP_200_OK
    return VehicleOut.of(rec, unchanged=not created)


def _preset_toml(name: str) -> str:
    return dump_toml(load_vehicle(name))


@router.get("", response_model=list[VehicleOut], summary="Vehicles (latest version of each)")
def list_vehicles(store: StoreDep) -> list[VehicleOut]:
    return [VehicleOut.of(v, brief=True) for v in store.list_vehicles()]


@router.get("/{name}", response_model=VehicleOut, summary="Latest version of a vehicle")
def get_vehicle(name: str, store: StoreDep) -> VehicleOut:
    return VehicleOut.of(store.get_vehicle(name))


@router.get("/{name}/versions", response_model=list[VehicleOut], summary="Every version of a vehicle")
def vehicle_versions(name: str, store: StoreDep) -> list[VehicleOut]:
    return [VehicleOut.of(v, brief=True) for v in store.vehicle_versions(name)]


@router.get("/{name}/versions/{version}", response_model=VehicleOut, summary="One version of a vehicle")
def vehicle_version(name: str, version: int, store: StoreDep) -> VehicleOut:
    return VehicleOut.of(store.get_vehicle(name, version))


@router.get("/{name}/versions/{version}/driveline", summary="The driveline TOML of a version",
            response_class=Response, responses={200: {"content": {"application/toml": {}}}})
def vehicle_driveline(name: str, version: int, store: StoreDep) -> Response:
    rec = store.get_vehicle(name, version)
    return Response(rec.driveline_path.read_bytes(), media_type="application/toml")


@router.get("/{name}/gap-sensitivity", response_model=GapSensitivityOut,
            summary="Gap what-ifs and sensitivities S1..S5 for the vehicle",
            responses={202: {"model": GapSensitivityJobOut,
                             "description": "computing (started by POST): its progress"}})
async def vehicle_gap_sensitivity(name: str, store: StoreDep,
                                  version: Annotated[int | None, Query(ge=1)] = None,
                                  compute: Annotated[bool, Query(description=(
                                      "false: only read; 404 gap_sensitivity_not_started when it was never "
                                      "computed nor started"))] = True) -> Any:
    """Each of the five gaps removed and halved under the paper's tip-in, with the nominal and
    no-backlash responses; computed on first request and kept beside the vehicle version. While a
    job started by ``POST`` computes it, ``202`` with the job's progress instead; ``compute=false``
    never computes: 404 ``gap_sensitivity_not_started``, or the error of a failed job.

    ``sensitivity_unit`` says what ``sensitivity`` is per: ``mm`` of circumferential clearance
    (the paper's definition; the vehicle gives every gap's contact radius) or ``rad`` of gap
    angle; ``sensitivity_per_mm`` (null without radii) and ``sensitivity_per_rad`` are both given."""
    rec = store.get_vehicle(name, version)
    doc = _cached(store, rec.name, rec.version)
    if doc is not None:
        return doc
    job = store.find_job("gap_sensitivity", gap_sensitivity_subject(rec.name, rec.version))
    if job is not None and job.status in (JobStatus.QUEUED, JobStatus.RUNNING):
        return _job_answer(rec.name, rec.version, job)
    if not compute and job is not None and job.status is JobStatus.FAILED:
        _job_answer(rec.name, rec.version, job)  # its error
    if not compute:
        raise NotFoundError(f"the gap sensitivity of {rec.name} v{rec.version} is not computed; start it with POST "
                            f"/vehicles/{rec.name}/gap-sensitivity?version={rec.version}",
                            code="gap_sensitivity_not_started")
    return await run_in_threadpool(gap_job.compute, store, rec.name, rec.version)


@router.post("/{name}/gap-sensitivity", status_code=status.HTTP_202_ACCEPTED, response_model=GapSensitivityJobOut,
             summary="Start computing the gap sensitivity in the background (poll GET for progress)",
             responses={200: {"model": GapSensitivityOut, "description": "already computed"}})
def start_gap_sensitivity(name: str, store: StoreDep, runner: RunnerDep, settings: SettingsDep,
                          version: Annotated[int | None, Query(ge=1)] = None) -> Any:
    rec = store.get_vehicle(name, version)
    doc = _cached(store, rec.name, rec.version)
    if doc is not None:
        return JSONResponse(doc)
    gap_sensitivity_work(load_vehicle(rec.driveline_path))  # past the limit: refused now, not in the background
    subject = gap_sensitivity_subject(rec.name, rec.version)
    job = store.find_job("gap_sensitivity", subject)
    if job is None or job.status in (JobStatus.FAILED, JobStatus.DONE):
        room_for_a_job(store, settings.max_queued_jobs)
        job = store.create_job("gap_sensitivity", subject)
        runner.submit(job.id)
    return _job_answer(rec.name, rec.version, job)


@router.get("/{name}/gap-sensitivity/status", response_model=JobStateOut,
            summary="Whether the gap sensitivity is computed, computing (with progress) or not started")
def gap_sensitivity_status(name: str, store: StoreDep,
                           version: Annotated[int | None, Query(ge=1)] = None) -> JobStateOut:
    rec = store.get_vehicle(name, version)
    if _cached(store, rec.name, rec.version) is not None:
        return JobStateOut(status="done", progress=1.0)
    return job_state(store.find_job("gap_sensitivity", gap_sensitivity_subject(rec.name, rec.version)))


def _cached(store: Store, name: str, version: int) -> dict[str, Any] | None:
    doc = store.artifacts.get("gap_sensitivity", gap_sensitivity_subject(name, version), "doc")
    if doc is not None and doc.get("format") == GAP_SENSITIVITY_FORMAT:  # older documents did not state the unit
        return doc
    return None


def _job_answer(name: str, version: int, job: JobRecord) -> JSONResponse:
    if job.status is JobStatus.FAILED:
        err = AppError(f"gap sensitivity of {name} v{version} failed: {job.error_detail}",
                       code=job.error_code or "gap_sensitivity_failed")
        err.status = JOB_ERROR_STATUS.get(job.error_code or "", 422)
        raise err
    return JSONResponse(status_code=status.HTTP_202_ACCEPTED, content=GapSensitivityJobOut(
        name=name, version=version, job_id=job.id, status=job.status.value, stage=job.stage,
        progress=job.progress).model_dump())


PROPOSAL_DOC = {
    "requestBody": {
        "content": {"multipart/form-data": {"schema": {"type": "object", "properties": {
            "log_id": {"type": "string", "description": "a stored log of the vehicle (POST /logs)"},
            "dbc": {"type": "string", "format": "binary", "description": "the vehicle's database (DBC/KCD/SYM/ARXML); "
                    "default: the project's dbc/lashscope_ev.dbc"},
            "map": {"type": "string", "description": "optional changes, one a line: ROLE=Message.Signal (ROLE=- drops "
                    "the channel), invert ROLE, keep ROLE"},
        }, "required": ["log_id"]}}},
        "required": True,
    }
}


@router.post("/signal-map-proposal", openapi_extra=PROPOSAL_DOC, response_model=SignalMapProposalOut,
             summary="Propose a signal map for a stored log and a DBC, with the evidence per channel")
async def propose_signal_map(request: Request, store: StoreDep, settings: SettingsDep) -> dict[str, Any]:
    """The map ``lashscope init`` proposes (:mod:`app.signal_proposal`): per channel the DBC signal, its unit and
    factor, rate (Hz), decoded range in the canonical unit, correlation and sign check, and the other candidates;
    ``signal_map_toml`` is the map to register (``POST /vehicles``, field ``signal_map``) as is or edited.
    ``missing`` lists the channels every analysis needs that no signal was found for. Nothing is stored."""
    up = await receive_upload(request, store.temp_path, MAX_FILE_BYTES["dbc"], 0, urlencoded_form=True,
                              idle_s=settings.upload_idle_s, max_files=1)
    files = {f.field_name: f.path for f in up.files}
    names = {f.path: f.filename for f in up.files}
    try:
        unknown = set(files) - {"dbc"}
        if unknown:
            raise InputError(f"unexpected file fields {sorted(unknown)}; use dbc")
        for f in up.files:
            if f.size > MAX_FILE_BYTES["dbc"]:
                raise UploadTooLargeError(f"dbc {f.filename!r} has {f.size} bytes, more than the "
                                          f"{MAX_FILE_BYTES['dbc'] // 1024} KiB a vehicle's dbc may have",
                                          code="vehicle_file_too_large")
        log_id = up.fields.get("log_id", "").strip()
        if not log_id:
            raise InputError("form field 'log_id' is required: a stored log (POST /logs)")
        log = store.get_log(log_id)
        overrides: dict[str, str | None] = {}
        fixed: dict[str, bool] = {}
        for line in (s.strip() for s in up.fields.get("map", "").splitlines()):
            word, _, role = line.partition(" ")
            if word in ("invert", "keep") and role.strip():
                if role.strip() not in CANONICAL:
                    raise InputError(f"map: {line!r}: not a channel; channels are {', '.join(CANONICAL)}",
                                     code="invalid_map_override")
                fixed[role.strip()] = word == "invert"
            elif line:
                overrides.update(parse_overrides([line]))
        dbc = files.get("dbc") or settings.dbc_dir / "lashscope_ev.dbc"
        names.setdefault(dbc, f"default {dbc.name}")
        names[log.path] = log.filename
        with user_file_names(names):  # reads a stored log of any size twice: in a child process, within limits
            proposal = await run_in_threadpool(
                run_bounded, "app.signal_proposal:propose", log.path, dbc, overrides, root=store.root,
                what=f"proposing a signal map for {log.filename}", setting="LASHSCOPE_VALIDATE_CPU_S",
                cpu_s=settings.validate_cpu_s, memory_mb=settings.bounded_memory_mb, kwargs={"invert": fixed})
    finally:
        for p in files.values():
            p.unlink(missing_ok=True)
    doc = proposal.to_dict()
    doc["log_id"] = log_id
    doc["database"] = names.get(dbc, dbc.name)
    return dict(json_safe(doc))
