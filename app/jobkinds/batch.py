"""Job kind ``batch``: the fleet batch pipeline (:func:`app.fleet.batch.run_batch`) over stored logs.

Subject: the batch id (``ba_<hex>``). The batch's folder (:func:`directory`, under the store's
``jobs/``) holds ``request.json`` (the log ids, vehicle, options), the batch output ``out/``
(``out/logs/<sha256>.json`` one record per log, ``out/events/`` the batch's own event store,
docs/fleet.md) and, once done, ``summary.json``. The batch runs in the job's worker process,
without Dask (the job already is the isolated worker). A batch resumed after a crash skips every
log whose record exists (the batch pipeline's skip-by-content-hash), so no log is analysed twice
and none is lost.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from app.errors import InputError
from app.fleet.batch import BatchConfig, run_batch
from app.fleet.work import BatchSpec
from app.jobkinds import progress_reporter
from app.jobkinds.diagnosis import write_json
from app.pipeline import AnalysisOptions, VehicleInputs
from app.storage.base import Store
from app.storage.records import JobRecord
from sim import load_vehicle

REQUEST, SUMMARY = "request.json", "summary.json"


def directory(store: Store, batch_id: str) -> Path:
    return store.job_dir(batch_id)


def records(out: Path) -> dict[str, dict[str, Any]]:
    """Every per-log record written so far, by the log's SHA-256."""
    found: dict[str, dict[str, Any]] = {}
    for path in sorted((out / "logs").glob("*.json")):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):  # removed meanwhile, or not ours
            continue
        found[path.stem] = doc
    return found


def run(store: Store, job: JobRecord) -> None:
    d = directory(store, job.subject)
    try:
        req = json.loads((d / REQUEST).read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(f"batch {job.subject} has no readable request", code="batch_not_found") from exc
    veh = store.get_vehicle(req["vehicle"], req["vehicle_version"])
    logs = [store.get_log(log_id) for log_id in req["log_ids"]]
    spec = BatchSpec(VehicleInputs(load_vehicle(veh.driveline_path), veh.database_path, veh.signal_map_path, veh.name),
                     AnalysisOptions.from_dict(req["options"]).to_dict(), bool(req["diagnose"]))
    cfg = BatchConfig(out=d / "out", spec=spec, vehicle_id=req["vehicle_id"], workers=0)
    progress = progress_reporter(store, job.id)
    done = [len(records(cfg.out))]  # logs finished by an earlier, cut-off attempt are skipped
    progress(done[0] / len(logs), "analysing")

    def on_record(record: dict[str, Any]) -> None:
        done[0] += 1
        progress(min(done[0], len(logs)) / len(logs), "analysing")

    summary = run_batch([str(rec.path) for rec in logs], cfg, stream=None, on_record=on_record)
    store.update_job(job.id, 0.99, "saving")
    found = records(cfg.out)  # by content hash; a log that could not be read is failed anyway
    ok = sum(1 for rec in logs if found.get(rec.sha256, {}).get("status") == "ok")
    write_json(d / SUMMARY, {
        "logs": len(logs), "ok": ok, "failed": len(logs) - ok,
        "events": sum(int(found.get(rec.sha256, {}).get("events", 0)) for rec in logs),
        "analysed_now": summary.ok + summary.failed, "skipped": summary.skipped,
        "elapsed_s": round(summary.elapsed_s, 3)})
