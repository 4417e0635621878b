"""Result documents as CSV tables, for ``format=csv`` on the JSON routes that are tables.

One row per analysed event; columns ``<metric>_measured``, ``<metric>_simulated``,
``<metric>_difference`` for every metric in :data:`app.analysis.metrics.METRIC_NAMES` (SI units
as in the JSON: rpm, s, Hz, -), then the aligned error and the event's tracking verdict, then the
acceleration's source and ``accel_<criterion>_<part>`` for every drivability criterion in
:data:`app.analysis.drivability.CRITERIA` (units there: m/s^2, m/s^3, m/s^1.75, s, Hz, -). Empty
cells are undefined values (JSON ``null``).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

from app.analysis.drivability import CRITERIA, CRITERIA_NAMES
from app.analysis.metrics import METRIC_NAMES

#: drivability columns (``accel_<criterion>_<part>``), appended after the ripple metrics; units in CRITERIA
DRIVABILITY_COLUMNS: tuple[str, ...] = tuple(
    f"accel_{c}_{part}" for c in CRITERIA_NAMES for part in ("measured", "simulated", "difference"))
DRIVABILITY_UNITS: dict[str, str] = {f"accel_{c}_{part}": CRITERIA[c] for c in CRITERIA_NAMES
                                     for part in ("measured", "simulated", "difference")}
METRIC_COLUMNS: tuple[str, ...] = (
    "event_index", "kind", "t_cross_s",
    *(f"{m}_{part}" for m in METRIC_NAMES for part in ("measured", "simulated", "difference")),
    "rms_rpm", "nrmse", "bias_rpm", "samples", "tracking",
    "accel_source", *DRIVABILITY_COLUMNS,
)
EVENT_COLUMNS: tuple[str, ...] = (
    "index", "kind", "t_cross_s", "t_start_s", "t_end_s", "torque_before_nm", "torque_after_nm",
    "torque_rate_nm_s", "motor_speed_rpm", "vehicle_speed_kmh", "pedal_before_pct", "pedal_after_pct",
    "from_coast", "included", "exclusion", "tracking",
)


def _cell(v: Any) -> Any:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return ""
    if isinstance(v, dict):  # a tracking verdict
        return v.get("verdict", "")
    return v


def csv_text(columns: Sequence[str], rows: Iterable[dict[str, Any]]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(columns)
    for r in rows:
        w.writerow([_cell(r.get(c)) for c in columns])
    return buf.getvalue()


def metrics_csv(events: list[dict[str, Any]]) -> str:
    """The ``/metrics`` events (``event_index``, ``measured``, ``simulated``, ``difference``, ...) as CSV."""
    rows = []
    for m in events:
        row = dict(m)
        feel = m.get("drivability") or {}
        row["accel_source"] = feel.get("source")
        for part in ("measured", "simulated", "difference"):
            for name in METRIC_NAMES:
                row[f"{name}_{part}"] = (m.get(part) or {}).get(name)
            for name in CRITERIA_NAMES:
                row[f"accel_{name}_{part}"] = (feel.get(part) or {}).get(name)
        rows.append(row)
    return csv_text(METRIC_COLUMNS, rows)


def events_csv(events: list[dict[str, Any]]) -> str:
    """The ``/events`` entries as CSV (``tracking`` reduced to its verdict)."""
    return csv_text(EVENT_COLUMNS, events)
