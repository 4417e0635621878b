from __future__ import annotations

from fastapi import APIRouter

from app import __version__
from app.api.deps import StoreDep
from app.api.schemas import HealthOut
from app.storage.dialect import database_errors

router = APIRouter(tags=["health"])


@router.get("/health", response_model=HealthOut, summary="Liveness, storage and job queue")
def health(store: StoreDep) -> HealthOut:
    """Open without a key (container health checks); names the data directory, never where it is."""
    try:
        jobs = store.job_counts()
        db = "ok"
    except database_errors() as exc:
        jobs, db = {}, f"error: {type(exc).__name__}"
    return HealthOut(status="ok" if db == "ok" else "degraded", version=__version__, data_dir=store.root.name,
                     database=db, jobs=jobs)
