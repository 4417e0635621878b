"""Job kind ``gap_sensitivity``: a vehicle version's gap what-ifs and sensitivities, in the background
with progress (one step per gap), for a page that starts it and shows how far it is.

Subject: ``<vehicle name>/v<version>`` (:func:`app.jobkinds.gap_sensitivity_subject`), also the id of the
``gap_sensitivity`` artefact the document is stored as (beside the vehicle version, atomically), where
``GET /vehicles/{name}/gap-sensitivity`` reads it.
"""

from __future__ import annotations

from typing import Any

from app.jobkinds import gap_sensitivity_subject, progress_reporter
from app.pipeline import gap_sensitivity
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import json_safe
from sim import load_vehicle


def compute(store: Store, name: str, version: int | None, progress: Any = None) -> dict[str, Any]:
    """The document of a vehicle version, computed (and kept beside it)."""
    rec = store.get_vehicle(name, version)
    vehicle = load_vehicle(rec.driveline_path)
    doc: dict[str, Any] = dict(json_safe(gap_sensitivity(vehicle, progress) if progress else gap_sensitivity(vehicle)))
    doc.update(name=rec.name, version=rec.version)
    store.artifacts.put("gap_sensitivity", gap_sensitivity_subject(rec.name, rec.version), "doc", doc)
    return doc


def run(store: Store, job: JobRecord) -> None:
    name, version = job.subject.rsplit("/v", 1)
    compute(store, name, int(version), progress_reporter(store, job.id))
