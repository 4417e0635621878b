"""Job kind ``identification``: :func:`app.identify.logs.identify_logs` over stored logs of one vehicle.

Subject: the identification id (``id_<hex>``), which names an ``identification`` artefact of the store
(:mod:`app.storage.artifacts`): its ``request`` (the log ids, the withheld logs, the vehicle and its
version, the base parameters to fit) and, once done, its ``result`` (the documented result of
:meth:`~app.identify.logs.IdentifyResult.to_dict`) and ``vehicle`` file (the identified vehicle with its
``[provenance]``), which ``POST /identifications/{id}/apply`` stores as a new version.
"""

from __future__ import annotations

import json
from typing import Any

from app.errors import InputError
from app.identify.logs import IdentifyOptions, identify_logs
from app.jobkinds import progress_reporter
from app.storage.base import Store
from app.storage.records import JobRecord
from sim import load_vehicle

KIND = "identification"


def request(store: Store, identification_id: str) -> dict[str, Any]:
    doc = store.artifacts.get(KIND, identification_id, "request")
    if doc is None:
        raise InputError(f"identification {identification_id} has no readable request",
                         code="identification_not_found")
    return doc


def run(store: Store, job: JobRecord) -> None:
    req = request(store, job.subject)
    veh = store.get_vehicle(req["vehicle"], req["vehicle_version"])
    records = {log_id: store.get_log(log_id) for log_id in [*req["log_ids"], *req["validate_log_ids"]]}
    logs = [records[log_id].path for log_id in req["log_ids"]]
    withheld = [records[log_id].path for log_id in req["validate_log_ids"]]
    names = {rec.path.name: rec.filename for rec in records.values()}
    progress = progress_reporter(store, job.id)
    options = IdentifyOptions(dbc=veh.database_path, signal_map=veh.signal_map_path, seed=int(req["seed"]),
                              params=tuple(req["params"]))
    result = identify_logs(logs, load_vehicle(veh.driveline_path), options, withheld,
                           progress)
    store.update_job(job.id, 0.99, "saving")
    val = result.validation
    for item in [*result.logs, *val.get("before", []), *val.get("after", [])]:
        key = "name" if "name" in item else "log"  # logs by their upload name: the stored file's stays inside
        item[key] = names.get(item[key], item[key])
    store.artifacts.put_text(KIND, job.subject, "vehicle", result.vehicle_toml(req["name"]))
    store.artifacts.put(KIND, job.subject, "result", json.loads(json.dumps(result.to_dict(), allow_nan=False)))
