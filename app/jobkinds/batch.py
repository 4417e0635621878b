"""Job kind ``batch``: the fleet batch pipeline (:func:`app.fleet.batch.run_batch`) over stored logs.

Subject: the batch id (``ba_<hex>``), which names a ``batch`` artefact of the store
(:mod:`app.storage.artifacts`): its ``request`` (the log ids, vehicle, options), its working folder
(:meth:`~app.storage.artifacts.Artifacts.workdir`: the batch output, one record per log and the batch's
own event store, docs/fleet.md, read with :func:`app.fleet.batch.read_records`) and, once done, its
``summary``. The batch runs in the job's worker process, without Dask (the job already is the isolated
worker). A batch resumed after a crash skips every log whose record exists (the batch pipeline's
skip-by-content-hash), so no log is analysed twice and none is lost.
"""

from __future__ import annotations

from typing import Any

from app.errors import InputError
from app.fleet.batch import BatchConfig, read_records, run_batch
from app.fleet.work import BatchSpec
from app.jobkinds import progress_reporter
from app.pipeline import AnalysisOptions, VehicleInputs
from app.storage.base import Store
from app.storage.records import JobRecord
from sim import load_vehicle

KIND = "batch"


def run(store: Store, job: JobRecord) -> None:
    req = store.artifacts.get(KIND, job.subject, "request")
    if req is None:
        raise InputError(f"batch {job.subject} has no readable request", code="batch_not_found")
    veh = store.get_vehicle(req["vehicle"], req["vehicle_version"])
    logs = [store.get_log(log_id) for log_id in req["log_ids"]]
    spec = BatchSpec(VehicleInputs(load_vehicle(veh.driveline_path), veh.database_path, veh.signal_map_path, veh.name),
                     AnalysisOptions.from_dict(req["options"]).to_dict(), bool(req["diagnose"]))
    cfg = BatchConfig(out=store.artifacts.workdir(KIND, job.subject), spec=spec, vehicle_id=req["vehicle_id"],
                      workers=0)
    progress = progress_reporter(store, job.id)
    done = [len(read_records(cfg.out))]  # logs finished by an earlier, cut-off attempt are skipped
    progress(done[0] / len(logs), "analysing")

    def on_record(record: dict[str, Any]) -> None:
        done[0] += 1
        progress(min(done[0], len(logs)) / len(logs), "analysing")

    summary = run_batch([str(rec.path) for rec in logs], cfg, stream=None, on_record=on_record)
    store.update_job(job.id, 0.99, "saving")
    found = read_records(cfg.out)  # by content hash; a log that could not be read is failed anyway
    ok = sum(1 for rec in logs if found.get(rec.sha256, {}).get("status") == "ok")
    store.artifacts.put(KIND, job.subject, "summary", {
        "logs": len(logs), "ok": ok, "failed": len(logs) - ok,
        "events": sum(int(found.get(rec.sha256, {}).get("events", 0)) for rec in logs),
        "analysed_now": summary.ok + summary.failed, "skipped": summary.skipped,
        "elapsed_s": round(summary.elapsed_s, 3)})
