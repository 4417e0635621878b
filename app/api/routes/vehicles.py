"""Vehicles: a driveline description (TOML) + DBC + signal map, versioned by name."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query, Request, Response, status
from fastapi.concurrency import run_in_threadpool

from app.api.deps import SettingsDep, StoreDep
from app.api.schemas import ERRORS, GapSensitivityOut, SignalMapProposalOut, VehicleOut
from app.api.upload import check_toml, receive_upload, user_file_names
from app.errors import InputError, UploadTooLargeError
from app.pipeline import GAP_SENSITIVITY_FORMAT, check_vehicle_files, gap_sensitivity
from app.storage.results import json_safe
from app.storage.sqlstore import check_vehicle_name
from sim import load_vehicle, preset_names

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
    from sim import dump_toml

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
            summary="Gap what-ifs and sensitivities S1..S5 for the vehicle")
async def vehicle_gap_sensitivity(name: str, store: StoreDep,
                                  version: Annotated[int | None, Query(ge=1)] = None) -> dict[str, Any]:
    """Each of the five gaps removed and halved under the paper's tip-in, with the nominal and
    no-backlash responses; computed on first request and kept beside the vehicle version.

    ``sensitivity_unit`` says what ``sensitivity`` is per: ``mm`` of circumferential clearance
    (the paper's definition; the vehicle gives every gap's contact radius) or ``rad`` of gap
    angle; ``sensitivity_per_mm`` (null without radii) and ``sensitivity_per_rad`` are both given."""
    rec = store.get_vehicle(name, version)
    cached = rec.driveline_path.parent / "gap_sensitivity.json"
    if cached.exists():
        doc: dict[str, Any] = json.loads(cached.read_text(encoding="utf-8"))
        if doc.get("format") == GAP_SENSITIVITY_FORMAT:  # older documents did not state the unit
            return doc
    vehicle = await run_in_threadpool(load_vehicle, rec.driveline_path)
    doc = json_safe(await run_in_threadpool(gap_sensitivity, vehicle))
    doc.update(name=rec.name, version=rec.version)
    tmp = cached.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc), encoding="utf-8")
    Path(tmp).replace(cached)
    return doc


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
    from app.ingest.signalmap import CANONICAL
    from app.signal_proposal import parse_overrides, propose

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
        with user_file_names(names):
            proposal = await run_in_threadpool(propose, log.path, dbc, overrides, invert=fixed)
    finally:
        for p in files.values():
            p.unlink(missing_ok=True)
    doc = proposal.to_dict()
    doc["log_id"] = log_id
    doc["database"] = names.get(dbc, dbc.name)
    return dict(json_safe(doc))
