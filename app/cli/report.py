"""Plain-text tables of an analysis document (events, metrics) for the command line."""

from __future__ import annotations

import math
from typing import Any

METRIC_ROWS = (
    ("fluctuation_rpm", "fluctuation peak-valley", "rpm", 1.0),
    ("rise_height_rpm", "rise height (gap open)", "rpm", 1.0),
    ("gap_open_time_s", "gap-open time (free rotor)", "ms", 1e3),
    ("rising_edge_time_s", "rising edge (upper bound)", "ms", 1e3),
    ("first_overshoot_rpm", "first overshoot", "rpm", 1.0),
    ("shuffle_freq_hz", "shuffle frequency", "Hz", 1.0),
    ("damping_ratio", "damping ratio", "-", 1.0),
    ("settling_time_s", "settling time", "s", 1.0),
)


METRIC_NOTES = [
    "  measured, simulated: medians over the analysed events; sim-meas: median of the per-event differences "
    "(not the difference of the two medians)",
    "  speed metrics on the motor speed detrended from the rigid-body trend in each event window (docs/metrics.md)",
]


def _f(v: Any, scale: float = 1.0, digits: int = 1) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "-"
    return f"{v * scale:.{digits}f}"


def events_table(doc: dict[str, Any]) -> str:
    lines = [f"{'#':>3} {'kind':<8} {'side':<6} {'t (s)':>8} {'torque (N m)':>15} {'rate (N m/s)':>12} {'km/h':>6}"
             "  status"]
    for e in doc["events"]:
        status = "analysed" if e["has_metrics"] else (e["exclusion"] or e["error"] or "-")
        tr = e.get("tracking") or {}
        if e["has_metrics"] and tr.get("verdict") == "poor":
            status += ", does not track: " + "; ".join(tr.get("reasons", []))
        side = "coast" if e.get("from_coast") else "regen"  # the not-driving side of the reversal
        torque = f"{e['torque_before_nm']:.0f} -> {e['torque_after_nm']:.0f}"
        lines.append(f"{e['index']:>3} {e['kind']:<8} {side:<6} {e['t_cross_s']:>8.2f} {torque:>15} "
                     f"{e['torque_rate_nm_s']:>12.0f} {_f(e['vehicle_speed_kmh']):>6}  {status}")
    return "\n".join(lines)


def metrics_table(doc: dict[str, Any]) -> str:
    summ = doc["summary"].get("metrics", {})
    lines = [f"{'metric (median over events)':<30} {'measured':>10} {'simulated':>10} {'sim-meas':>10}  unit"]
    for key, label, unit, scale in METRIC_ROWS:
        row = summ.get(key)
        if not row:
            continue
        digits = 3 if unit in ("-", "s") else 1
        lines.append(f"{label:<30} {_f(row['measured_median'], scale, digits):>10} "
                     f"{_f(row['simulated_median'], scale, digits):>10} "
                     f"{_f(row['difference_median'], scale, digits):>10}  {unit}")
    for key, label in (("rms_rpm", "aligned speed RMS error"), ("nrmse", "aligned speed NRMSE")):
        row = summ.get(key)
        if row:
            lines.append(f"{label:<30} {'':>10} {'':>10} {_f(row['difference_median'], 1.0, 3):>10}  "
                         f"{'rpm' if key == 'rms_rpm' else '-'}")
    lines += METRIC_NOTES
    labels = {key: label for key, label, _, _ in METRIC_ROWS}
    for key, why in (doc["summary"].get("resolution") or {}).items():
        lines.append(f"  {labels.get(key, key)}: {why}")
    return "\n".join(lines)


DRIVABILITY_ROWS = (
    ("response_delay_s", "response delay (pedal -> rise)", "ms", 1e3),
    ("kick_ms2", "kick (1st peak over settled)", "m/s^2", 1.0),
    ("shuffle_pp_ms2", "shuffle peak-to-peak", "m/s^2", 1.0),
    ("shuffle_freq_hz", "shuffle frequency (accel)", "Hz", 1.0),
    ("shuffle_damping_ratio", "shuffle damping ratio", "-", 1.0),
    ("max_jerk_ms3", "maximum jerk", "m/s^3", 1.0),
    ("clunk_ms2", "clunk (HF peak at closure)", "m/s^2", 1.0),
    ("vdv_ms175", "VDV (ISO 2631-1 Wd)", "m/s^1.75", 1.0),
    ("settled_accel_ms2", "settled accel.", "m/s^2", 1.0),
)


def drivability_table(doc: dict[str, Any]) -> str:
    """The drivability criteria (median over events, measured and simulated) and where the acceleration comes
    from; empty when the analysis has none."""
    summ = doc["summary"].get("drivability") or {}
    if not summ:
        return ""
    src = doc.get("acceleration") or {}
    where = src.get("kind", "-")
    if src.get("bandwidth_hz"):
        where += f", derived with {src['bandwidth_hz']:.1f} Hz bandwidth"
    if src.get("note"):
        where += f"; {src['note']}"
    lines = [f"{'drivability (median over events)':<30} {'measured':>10} {'simulated':>10} {'sim-meas':>10}  unit"
             f"   acceleration: {where}"]
    for key, label, unit, scale in DRIVABILITY_ROWS:
        row = summ.get(key)
        if not row:
            continue
        digits = 0 if unit == "ms" else (1 if unit == "m/s^3" else 3 if unit == "-" else 2)
        # a criterion signed in the vehicle's frame (the settled acceleration) has medians per event kind only
        parts = ([(f"{label} ({kind.replace('_', '-')})", row[kind]) for kind in ("tip_in", "tip_out")
                  if isinstance(row.get(kind), dict) and row[kind].get("events")]
                 if _f(row.get("measured_median")) == "-" and "tip_in" in row else [(label, row)])
        for text, r in parts:
            lines.append(f"{text:<30} {_f(r['measured_median'], scale, digits):>10} "
                         f"{_f(r['simulated_median'], scale, digits):>10} "
                         f"{_f(r['difference_median'], scale, digits):>10}  {unit}")
    rating = doc["summary"].get("rating")
    if rating:
        lines.append(f"rating (model {rating['model']}, CV RMS {rating['cv_rms']:.2f}): median "
                     f"{_f(rating['median'], 1.0, 1)} over {rating['events']} events")
    return "\n".join(lines)


def finding_lines(doc: dict[str, Any]) -> list[str]:
    """One warning per problem of the log as decoded (:mod:`app.analysis.logchecks`), with its code."""
    return [f"WARNING [{f['code']}]: {f['message']}" for f in doc["summary"].get("findings") or []]


def tracking_lines(doc: dict[str, Any]) -> list[str]:
    """A warning above the medians when the simulation does not track the measurement (empty when it does)."""
    tr = doc["summary"].get("tracking") or {}
    if tr.get("verdict") == "good":
        return []
    head = ("WARNING: the simulation does not track this log; the differences below are not a valid comparison:"
            if tr.get("verdict") == "poor" else "WARNING: tracking could not be judged:")
    return [head, *(f"  - {r}" for r in tr.get("reasons", []))]


def summary_line(doc: dict[str, Any]) -> str:
    s = doc["summary"]
    whole = doc.get("whole") or {}
    return (f"{s['events']} events ({s['tip_in']} tip-in, {s['tip_out']} tip-out): {s['with_metrics']} analysed, "
            f"{s['excluded']} excluded; {_offset_text(doc)}; whole-log speed RMS "
            f"{_f(whole.get('rms_rpm'))} rpm; tracking {(s.get('tracking') or {}).get('verdict', '-')}")


def _offset_text(doc: dict[str, Any]) -> str:
    s, off = doc["summary"], doc.get("offset") or {}
    if s.get("offset_applied", True):
        return f"torque-to-speed offset {_f(s['offset_ms'])} ms"
    return (f"torque-to-speed offset not applied (estimate {_f(off.get('lag_s'), 1e3)} ms at correlation "
            f"{_f(off.get('correlation'), 1.0, 2)})")


def identified_param(p: dict[str, Any]) -> str:
    """One identified base parameter of an identification document: value [interval] unit, the file's, flags."""
    if not p["identified"]:
        return f"not identified ({p['note']}); kept at {p['nominal']:.4g}"
    ratio = f"{p['value'] / p['nominal']:.2f}x" if p["nominal"] else "-"
    flag = "  OFF THE FILE" if p["named"] else ""
    flag += "  AT PRIOR BOUND" if p["at_bound"] else ""
    return (f"{p['value']:.4g} [{p['lo']:.4g}, {p['hi']:.4g}] {p['unit']}   file {p['nominal']:.4g}   "
            f"{ratio}{flag}")


def read_lines(read: dict[str, Any] | None, label: str = "") -> list[str]:
    """A damaged or truncated log stated before the answer: ``WARNING [log_truncated]: the log is truncated
    (...); about 9693 frame(s) (19.4 s) lost; ...`` (nothing for an undamaged log)."""
    if not read or not read.get("damaged"):
        return []
    code = "log_truncated" if read.get("truncated") else "log_damaged"
    return [f"WARNING [{code}]: {label}{read['note']}"]
