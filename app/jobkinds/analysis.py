"""Job kind ``analysis``: a log through the whole pipeline with a vehicle; results to the analysis' directory.

Subject: the analysis id. The results are written atomically (:func:`app.storage.results.write_result`),
so a worker killed mid-write (timeout, cancellation, a killed server) leaves no half result. The stored
document (built once) also feeds the event-store hook (:func:`app.fleet.hook.after_analysis`), with the
SHA-256 the upload stored for the log.
"""

from __future__ import annotations

from app.fleet.hook import after_analysis
from app.jobkinds import progress_reporter
from app.payload import result_payload
from app.pipeline import AnalysisOptions, VehicleInputs, run_analysis
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import write_result
from sim import load_vehicle


def run(store: Store, job: JobRecord) -> None:
    rec = store.get_analysis(job.subject)
    logrec = store.get_log(rec.log_id)
    veh = store.get_vehicle(rec.vehicle_name, rec.vehicle_version)
    inputs = VehicleInputs(load_vehicle(veh.driveline_path), veh.database_path, veh.signal_map_path, veh.name)
    result = run_analysis(logrec.path, inputs, AnalysisOptions.from_dict(rec.options),
                          progress_reporter(store, job.id))
    store.update_job(job.id, 0.99, "saving")
    doc, arrays = result_payload(result)
    after_analysis(logrec.path, inputs, doc, log_hash=logrec.sha256)
    write_result(rec.result_dir, doc, arrays)
    store.set_analysis_summary(rec.id, doc["summary"])
