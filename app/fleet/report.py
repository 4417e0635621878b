r"""The fleet report: per vehicle, the lash estimate with an interval and the ripple over time; outliers flagged.

From the event store (:mod:`app.fleet.store`), events with metrics only:

- **gap-open time** (s): the measured free-rotor interval (``measured_gap_open_time_s``,
  :mod:`app.analysis.lash`); per vehicle its median with a bootstrap interval of the median
  (``level``, default 90 %, fixed seed);
- **total lash** (motor-referred, degrees): while the gap is open the rotor's speed relative to
  the still-loaded side grows about linearly from 0 to the rise height ``h`` (rpm), so the angle
  it travels is about ``theta = 1/2 * h * pi/30 * t_open`` (rad). An estimate, good for comparing
  vehicles of one driveline and for wear trends, not an absolute clearance; same interval method;
- **ripple**: the measured peak-to-valley fluctuation (rpm), median per vehicle and per ISO week;
- **per log** (``per_log``, oldest first): the same medians with intervals over each log's events, with
  the log's content hash, start time (the first event's absolute time) and tracking verdict, so a
  plot over time can link each point to the analyses of that log;
- **band**: over the vehicles' medians, fleet median +- ``k`` x 1.4826 x MAD (``k`` = 3; the MAD
  floored at 2 % of the median so identical vehicles do not flag noise). A vehicle whose median
  gap-open time, total lash or ripple lies outside is flagged with the reason. Needs at least
  three vehicles; with fewer no band is drawn and nothing is flagged.

Events of logs whose tracking verdict is ``poor`` (``log_tracking``, :mod:`app.analysis.tracking`:
the simulation does not follow the measured speed, so the comparison behind the metrics is not
valid) are left out of every figure unless ``include_poor`` is set; ``poor_tracking`` says how
many events and logs that was, and each vehicle's ``events_poor_tracking`` its share.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from app.fleet.store import read_events, weekly_median
from sim.units import rpm_to_rad_s

QUANTITIES = {  # report key -> (unit, what)
    "gap_open_time_ms": ("ms", "median measured gap-open time"),
    "total_lash_deg": ("deg", "median total lash, motor-referred (estimate)"),
    "ripple_rpm": ("rpm", "median measured fluctuation"),
}
MIN_VEHICLES_FOR_BAND = 3
MAD_FLOOR = 0.02
COLUMNS = ("vehicle", "log_hash", "log_name", "time", "measured_gap_open_time_s", "measured_rise_height_rpm",
           "measured_fluctuation_rpm", "log_tracking")
POOR = "poor"


def median_interval(values: np.ndarray, level: float, rng: np.random.Generator,
                    n_boot: int = 400) -> tuple[float, float, float]:
    """Median and its bootstrap percentile interval at ``level``; NaNs when ``values`` is empty."""
    v = values[np.isfinite(values)]
    if v.size == 0:
        return (float("nan"),) * 3
    if v.size == 1:
        return float(v[0]), float(v[0]), float(v[0])
    meds = np.median(rng.choice(v, size=(n_boot, v.size), replace=True), axis=1)
    lo, hi = np.quantile(meds, [(1 - level) / 2, (1 + level) / 2])
    return float(np.median(v)), float(lo), float(hi)


def _lash_deg(part: Any) -> np.ndarray:
    gap_s = part["measured_gap_open_time_s"].to_numpy(dtype=float)
    rise = part["measured_rise_height_rpm"].to_numpy(dtype=float)
    return np.asarray(np.degrees(rpm_to_rad_s(0.5 * rise) * gap_s), dtype=float)


def _per_log(part: Any, level: float, rng: np.random.Generator) -> list[dict[str, Any]]:
    """One vehicle's logs, oldest first: lash and ripple medians with intervals over each log's events."""
    out = []
    for log_hash, rows in part.groupby("log_hash", sort=False):
        times = rows["time"].dropna()
        out.append({
            "log_hash": str(log_hash), "events": len(rows),
            "log_name": str(rows["log_name"].iloc[0]) if rows["log_name"].notna().any() else str(log_hash),
            "time": times.min().isoformat() if len(times) else None,
            "tracking": str(rows["log_tracking"].iloc[0]) if rows["log_tracking"].notna().any() else None,
            **{q: dict(zip(("median", "lo", "hi"), median_interval(v, level, rng), strict=True))
               for q, v in (("total_lash_deg", _lash_deg(rows)),
                            ("ripple_rpm", rows["measured_fluctuation_rpm"].to_numpy(dtype=float)))}})
    return sorted(out, key=lambda r: (r["time"] is None, r["time"] or "", r["log_hash"]))


def _band(medians: list[float], k: float) -> dict[str, float] | None:
    m = np.asarray([x for x in medians if np.isfinite(x)])
    if m.size < MIN_VEHICLES_FOR_BAND:
        return None
    center = float(np.median(m))
    spread = max(1.4826 * float(np.median(np.abs(m - center))), MAD_FLOOR * abs(center))
    return {"center": center, "lo": center - k * spread, "hi": center + k * spread}


def fleet_report(root: str | Path, k: float = 3.0, level: float = 0.9, seed: int = 0,
                 include_poor: bool = False) -> dict[str, Any]:
    """Per-vehicle estimates, the fleet bands and the flags (see the module docstring)."""
    frame = read_events(root, columns=COLUMNS)
    frame = frame[np.isfinite(frame["measured_fluctuation_rpm"].to_numpy(dtype=float))]
    poor = (frame["log_tracking"] == POOR).to_numpy(dtype=bool)
    poor_by_vehicle = frame[poor].groupby("vehicle").size()
    poor_tracking = {"events": int(poor.sum()), "logs": int(frame.loc[poor, "log_hash"].nunique()),
                     "included": include_poor}
    if not include_poor:
        frame = frame[~poor]
    weekly = weekly_median(frame)
    rng = np.random.default_rng(seed)
    rng_logs = np.random.default_rng(seed + 1)  # its own draws: the per-vehicle intervals stay as they were
    vehicles: list[dict[str, Any]] = []
    for name, part in sorted(frame.groupby("vehicle"), key=lambda kv: str(kv[0])):
        gap_s = part["measured_gap_open_time_s"].to_numpy(dtype=float)
        lash_deg = _lash_deg(part)
        est = {"gap_open_time_ms": median_interval(gap_s * 1e3, level, rng),
               "total_lash_deg": median_interval(lash_deg, level, rng),
               "ripple_rpm": median_interval(part["measured_fluctuation_rpm"].to_numpy(dtype=float), level, rng)}
        times = part["time"].dropna()
        weeks = weekly[weekly["vehicle"] == name]
        vehicles.append({
            "vehicle": str(name), "events": len(part), "logs": int(part["log_hash"].nunique()),
            "events_with_gap_open_time": int(np.isfinite(gap_s).sum()),
            "events_poor_tracking": int(poor_by_vehicle.get(name, 0)),
            "first": times.min().isoformat() if len(times) else None,
            "last": times.max().isoformat() if len(times) else None,
            **{q: {"median": m, "lo": lo, "hi": hi} for q, (m, lo, hi) in est.items()},
            "weekly_ripple_rpm": [{"week": str(w), "events": int(n), "median": float(v)}
                                  for w, n, v in zip(weeks["week"], weeks["events"], weeks["median"], strict=True)],
            "flags": [],
            "outside": [],  # the quantities (QUANTITIES keys) whose band the vehicle lies outside
            "per_log": _per_log(part, level, rng_logs),
        })
    bands = {q: _band([v[q]["median"] for v in vehicles], k) for q in QUANTITIES}
    for v in vehicles:
        for q, band in bands.items():
            value = v[q]["median"]
            if band is not None and np.isfinite(value) and not band["lo"] <= value <= band["hi"]:
                unit, what = QUANTITIES[q]
                side = "above" if value > band["hi"] else "below"
                v["flags"].append(f"{what} {value:.3g} {unit} {side} the fleet band "
                                  f"[{band['lo']:.3g}, {band['hi']:.3g}] {unit}")
                v["outside"].append(q)
    return {"store": str(root), "vehicles": vehicles, "bands": bands, "band_k": k, "interval_level": level,
            "poor_tracking": poor_tracking,
            "units": {q: u for q, (u, _) in QUANTITIES.items()},
            "flagged": [v["vehicle"] for v in vehicles if v["flags"]]}


def point_colour(vehicle: dict[str, Any], quantity: str) -> str:
    """A vehicle's colour on the panel of ``quantity``: red only when it lies outside *that* quantity's band (the
    band drawn behind it), orange when only another quantity flags it, blue otherwise."""
    if quantity in vehicle.get("outside", ()):
        return "tab:red"
    return "tab:orange" if vehicle.get("flags") else "tab:blue"


def report_png(report: dict[str, Any], path: Path) -> Path:
    """Two panels: total lash per vehicle with intervals and the fleet band; weekly median ripple over time."""
    import matplotlib  # lazy: matplotlib only for the PNG; the server imports this module for the report's numbers

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after choosing the Agg backend

    vehicles = report["vehicles"]
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(10, 7.5))
    x = np.arange(len(vehicles))
    for i, v in enumerate(vehicles):
        q = v["total_lash_deg"]
        color = point_colour(v, "total_lash_deg")
        ax1.errorbar([i], [q["median"]], yerr=[[q["median"] - q["lo"]], [q["hi"] - q["median"]]], fmt="o",
                     color=color, capsize=4)
    band = report["bands"]["total_lash_deg"]
    if band is not None:
        ax1.axhspan(band["lo"], band["hi"], color="0.85", zorder=0, label=f"fleet band (±{report['band_k']:g} MAD)")
        ax1.axhline(band["center"], color="0.5", lw=1)
        ax1.legend(loc="best")
    ax1.set_xticks(x, [v["vehicle"] for v in vehicles], rotation=30, ha="right")
    ax1.set_ylabel("total lash, motor side (deg)")
    ax1.set_title(f"lash estimate per vehicle, median and {100 * report['interval_level']:.0f} % interval "
                  "(red: outside this band; orange: flagged on gap-open time or ripple)", fontsize="medium")
    for v in vehicles:
        weeks = v["weekly_ripple_rpm"]
        if weeks:
            ax2.plot([np.datetime64(w["week"]) for w in weeks], [w["median"] for w in weeks], marker="o",
                     label=v["vehicle"], color="tab:red" if "ripple_rpm" in v["outside"] else None)
    ax2.set_ylabel("median fluctuation per week (rpm)")
    ax2.set_title("ripple over time (red: median ripple outside the fleet band)")
    if any(v["weekly_ripple_rpm"] for v in vehicles):
        ax2.legend(loc="best", fontsize="small", ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path
