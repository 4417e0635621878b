"""Job kind ``gap_sensitivity``: a vehicle version's gap what-ifs and sensitivities, in the background
with progress (one step per gap), for a page that starts it and shows how far it is.

Subject: ``<vehicle name>/v<version>`` (:func:`subject`); the document is written beside the vehicle
version (:func:`cache_path`), atomically, where ``GET /vehicles/{name}/gap-sensitivity`` reads it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from app import atomic
from app.jobkinds import progress_reporter
from app.pipeline import gap_sensitivity
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import json_safe
from sim import load_vehicle


def subject(name: str, version: int) -> str:
    return f"{name}/v{version}"


def cache_path(driveline_path: Path) -> Path:
    return driveline_path.parent / "gap_sensitivity.json"


def write_cached(driveline_path: Path, doc: dict[str, Any]) -> None:
    atomic.write_text(cache_path(driveline_path), json.dumps(doc))


def compute(store: Store, name: str, version: int | None, progress: Any = None) -> dict[str, Any]:
    """The document of a vehicle version, computed (and kept beside it)."""
    rec = store.get_vehicle(name, version)
    vehicle = load_vehicle(rec.driveline_path)
    doc: dict[str, Any] = dict(json_safe(gap_sensitivity(vehicle, progress) if progress else gap_sensitivity(vehicle)))
    doc.update(name=rec.name, version=rec.version)
    write_cached(rec.driveline_path, doc)
    return doc


def run(store: Store, job: JobRecord) -> None:
    name, version = job.subject.rsplit("/v", 1)
    compute(store, name, int(version), progress_reporter(store, job.id))
