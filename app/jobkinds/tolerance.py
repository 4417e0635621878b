"""Job kind ``tolerance``: the Monte Carlo ripple band of a finished analysis over the vehicle's tolerances.

Subject: ``<analysis id>/n=<n>/seed=<seed>`` (:func:`app.jobkinds.tolerance_subject`), which is also the id
of the ``tolerance`` artefact (its ``band``) the worker stores, atomically, beside the analysis' results,
so it is computed once per ``(n, seed)``.
"""

from __future__ import annotations

from app.jobkinds import progress_reporter
from app.pipeline import tolerance_for_result
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import ResultFiles, json_safe
from sim import load_vehicle


def run(store: Store, job: JobRecord) -> None:
    analysis_id, n_part, seed_part = job.subject.split("/")
    n, seed = int(n_part.removeprefix("n=")), int(seed_part.removeprefix("seed="))
    rec = store.get_analysis(analysis_id)
    veh = store.get_vehicle(rec.vehicle_name, rec.vehicle_version)
    progress = progress_reporter(store, job.id)
    doc = tolerance_for_result(ResultFiles(rec.result_dir), load_vehicle(veh.driveline_path), n, seed,
                               progress)
    doc.update(analysis_id=analysis_id, vehicle=rec.vehicle_name, vehicle_version=rec.vehicle_version)
    store.artifacts.put("tolerance", job.subject, "band", json_safe(doc))
