"""One event-store row per event of an analysed log, from the stored analysis document.

The rows are built from the JSON document of :func:`app.payload.result_payload` (what the
service stores and the batch writes), so an upload and a batch run give the same rows. Columns
(units in the names; ``NaN``/null where a value is not determinable)::

    log_hash, log_name, source ("batch" | "service"), analysed_at (UTC), driveline
    event_index, kind (tip_in | tip_out), included, exclusion, error
    time (UTC; null when the log records no absolute start), t_log_s (s since the log's start),
    time_is_absolute
    vehicle_speed_kmh, motor_speed_rpm, torque_before_nm, torque_after_nm, torque_step_nm (after - before),
    torque_rate_nm_s
    measured_<metric>, simulated_<metric>   every ripple metric (app.analysis.metrics.METRIC_NAMES)
    accel_source, measured_accel_<criterion>, simulated_accel_<criterion>   every drivability criterion
                                            (app.analysis.drivability.CRITERIA; m/s^2, m/s^3, m/s^1.75, s, Hz)
    rating                                  1-10 score of a fitted rating model (app.analysis.ratings), else null
    sim_gap_open_time_s (the simulator's own gap-open interval), rms_rpm, nrmse
    tracking (event verdict: good | poor | unknown), log_tracking (the whole log's verdict)
    diagnosis_status, diagnosis_top ("+"-joined effects) when the log was diagnosed

``vehicle`` and ``date`` (UTC day of ``time``, ``"unknown"`` without an absolute time) choose the
dataset's partition (:mod:`app.fleet.store`: vehicle and month); ``date`` is also a column.
A log's start time is taken as UTC when the format records local time without a zone (BLF).
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta
from typing import Any

from app.analysis.drivability import CRITERIA_NAMES
from app.analysis.metrics import METRIC_NAMES

FLOAT_COLUMNS: tuple[str, ...] = (
    "t_log_s", "vehicle_speed_kmh", "motor_speed_rpm", "torque_before_nm", "torque_after_nm", "torque_step_nm",
    "torque_rate_nm_s", *(f"measured_{m}" for m in METRIC_NAMES), *(f"simulated_{m}" for m in METRIC_NAMES),
    "sim_gap_open_time_s", "rms_rpm", "nrmse",
    *(f"measured_accel_{c}" for c in CRITERIA_NAMES), *(f"simulated_accel_{c}" for c in CRITERIA_NAMES),
    "rating",
)
STRING_COLUMNS: tuple[str, ...] = (
    "log_hash", "log_name", "source", "driveline", "kind", "exclusion", "error", "tracking", "log_tracking",
    "diagnosis_status", "diagnosis_top", "accel_source",
)
NAN = float("nan")


def start_time(doc: dict[str, Any]) -> datetime | None:
    """The log's absolute start (UTC) from the analysis document's ingest summary, or None."""
    text = (doc.get("ingest") or {}).get("start_time")
    if not text:
        return None
    t = datetime.fromisoformat(text)
    return t.replace(tzinfo=UTC) if t.tzinfo is None else t.astimezone(UTC)


def _num(value: Any) -> float:
    return NAN if value is None else float(value)


def event_rows(doc: dict[str, Any], *, vehicle: str, log_hash: str, log_name: str, source: str,
               driveline: str, diagnosis: dict[str, Any] | None = None,
               analysed_at: datetime | None = None) -> list[dict[str, Any]]:
    """The rows of every event in ``doc``, each with its partition keys ``vehicle`` and ``date``.

    ``diagnosis`` is the diagnosis report's ``decision`` (``status``, ``top``) when the log was
    diagnosed; the same outcome goes on each of the log's rows.
    """
    start = start_time(doc)
    when = (analysed_at or datetime.now(UTC)).astimezone(UTC)
    metrics = {m["event_index"]: m for m in doc.get("metrics", [])}
    log_verdict = (doc.get("tracking") or {}).get("verdict")
    diag_status = diagnosis.get("status") if diagnosis else None
    diag_top = ("+".join(diagnosis.get("top") or []) or None) if diagnosis else None
    rows: list[dict[str, Any]] = []
    for ev in doc.get("events", []):
        t_abs = start + timedelta(seconds=float(ev["t_cross_s"])) if start is not None else None
        m = metrics.get(ev["index"], {})
        meas, sim = m.get("measured") or {}, m.get("simulated") or {}
        before, after = _num(ev.get("torque_before_nm")), _num(ev.get("torque_after_nm"))
        row: dict[str, Any] = {
            "vehicle": vehicle, "date": t_abs.date().isoformat() if t_abs is not None else "unknown",
            "log_hash": log_hash, "log_name": log_name, "source": source, "driveline": driveline,
            "analysed_at": when, "event_index": int(ev["index"]), "kind": ev["kind"],
            "included": bool(ev.get("included", ev.get("exclusion") is None)),
            "exclusion": ev.get("exclusion"), "error": ev.get("error"),
            "time": t_abs, "t_log_s": float(ev["t_cross_s"]), "time_is_absolute": t_abs is not None,
            "vehicle_speed_kmh": _num(ev.get("vehicle_speed_kmh")), "motor_speed_rpm": _num(ev.get("motor_speed_rpm")),
            "torque_before_nm": before, "torque_after_nm": after, "torque_step_nm": after - before,
            "torque_rate_nm_s": _num(ev.get("torque_rate_nm_s")),
            "sim_gap_open_time_s": _num(m.get("sim_gap_open_time_s")), "rms_rpm": _num(m.get("rms_rpm")),
            "nrmse": _num(m.get("nrmse")),
            "tracking": ((ev.get("tracking") or {}).get("verdict")), "log_tracking": log_verdict,
            "diagnosis_status": diag_status, "diagnosis_top": diag_top,
        }
        for name in METRIC_NAMES:
            row[f"measured_{name}"] = _num(meas.get(name))
            row[f"simulated_{name}"] = _num(sim.get(name))
        feel = m.get("drivability") or {}
        row["accel_source"] = feel.get("source")
        row["rating"] = _num((feel.get("rating") or {}).get("score"))
        for name in CRITERIA_NAMES:
            row[f"measured_accel_{name}"] = _num((feel.get("measured") or {}).get(name))
            row[f"simulated_accel_{name}"] = _num((feel.get("simulated") or {}).get(name))
        rows.append(row)
    return rows
