"""``GET /fleet``: the fleet report (docs/fleet.md) over the service's own event store.

The store is the one the analyses write to (``LASHSCOPE_EVENT_STORE``, by default
``<data dir>/events``); no path comes from the request, so the API reads nothing outside its
data. The plot is the CLI's (``lashscope fleet``); this answers with the numbers.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query

from app.api.deps import SettingsDep, StoreDep
from app.api.schemas import ERRORS, FleetOut
from app.errors import NotFoundError
from app.fleet.hook import store_dir
from app.fleet.report import fleet_report
from app.storage.results import json_safe

router = APIRouter(tags=["fleet"], responses=ERRORS)


@router.get("/fleet", response_model=FleetOut,
            summary="Per-vehicle lash estimate and ripple over time from the event store; outliers flagged")
def fleet(settings: SettingsDep, store: StoreDep, band_k: Annotated[float, Query(gt=0, le=20)] = 3.0,
          include_poor_tracking: bool = False) -> dict[str, Any]:
    """Each vehicle's ``per_log`` point names its stored log (``log_id``, null when the log came from a
    batch and is not stored here) and the analyses of that log (newest first), to link to them."""
    root = store_dir() or settings.data_dir / "events"
    try:
        report = fleet_report(root, k=band_k, include_poor=include_poor_tracking)
    except NotFoundError as exc:  # its message names the server path
        raise NotFoundError("no events stored yet: each finished analysis adds its events",
                            code="no_event_store") from exc
    report["store"] = "events"  # the data dir's layout, not a server path
    for v in report["vehicles"]:
        for point in v["per_log"]:
            log = store.find_log_by_hash(point["log_hash"])
            point["log_id"] = log.id if log is not None else None
            point["analyses"] = [{"id": a.id, "vehicle": a.vehicle_name, "version": a.vehicle_version,
                                  "status": a.job.status.value} for a in store.list_analyses(log.id)] if log else []
    return dict(json_safe(report))
