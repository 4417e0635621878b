"""Measured versus simulated: metric differences and aligned-speed error per event."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.analysis.metrics import METRIC_NAMES, RippleMetrics
from app.analysis.series import FloatArray
from app.serial import Serial, rule


@dataclass(frozen=True)
class SpeedError:
    rms_rpm: float  # root mean square of (simulated - measured) over the common samples
    nrmse: float  # rms_rpm / (max - min of the measured speed over the same samples)
    bias_rpm: float  # mean of (simulated - measured)
    samples: int


@dataclass(frozen=True)
class EventComparison(Serial):
    event_index: int
    measured: RippleMetrics
    simulated: RippleMetrics
    difference: dict[str, float]  # simulated - measured, per metric name
    error: SpeedError = field(metadata=rule(flatten=True))


def speed_error(measured: FloatArray, simulated: FloatArray) -> SpeedError:
    """Error of ``simulated`` against ``measured`` (rpm) on a common time base, shape (n,) each."""
    ok = np.isfinite(measured) & np.isfinite(simulated)
    if not ok.any():
        nan = float("nan")
        return SpeedError(nan, nan, nan, 0)
    err = simulated[ok] - measured[ok]
    rms = float(np.sqrt(np.mean(err * err)))
    span = float(np.ptp(measured[ok]))
    return SpeedError(rms, rms / span if span > 0 else float("nan"), float(np.mean(err)), int(ok.sum()))


def metric_difference(measured: RippleMetrics, simulated: RippleMetrics) -> dict[str, float]:
    """``simulated - measured`` for every metric in :data:`METRIC_NAMES` (NaN if either is NaN)."""
    m, s = measured.values(), simulated.values()
    return {k: s[k] - m[k] for k in METRIC_NAMES}


def compare_event(
    event_index: int, measured: RippleMetrics, simulated: RippleMetrics,
    measured_speed: FloatArray, simulated_speed: FloatArray,
) -> EventComparison:
    return EventComparison(event_index, measured, simulated, metric_difference(measured, simulated),
                           speed_error(measured_speed, simulated_speed))


def summarize(comparisons: list[EventComparison]) -> dict[str, dict[str, float]]:
    """Per metric: median measured, median simulated, median and mean difference over events."""
    out: dict[str, dict[str, float]] = {}
    for k in (*METRIC_NAMES, "rms_rpm", "nrmse"):
        if k in METRIC_NAMES:
            meas = np.array([getattr(c.measured, k) for c in comparisons], float)
            sim = np.array([getattr(c.simulated, k) for c in comparisons], float)
            diff = sim - meas
        else:
            meas = sim = np.full(len(comparisons), np.nan)
            diff = np.array([getattr(c.error, k) for c in comparisons], float)
        out[k] = {
            "measured_median": _nanmedian(meas),
            "simulated_median": _nanmedian(sim),
            "difference_median": _nanmedian(diff),
            "difference_mean": float(np.nanmean(diff)) if np.isfinite(diff).any() else float("nan"),
            "events": int(np.isfinite(diff).sum()),
        }
    return out


def _nanmedian(x: FloatArray) -> float:
    return float(np.nanmedian(x)) if np.isfinite(x).any() else float("nan")


def resolution_reasons(comparisons: list[EventComparison]) -> dict[str, str]:
    """Per metric the sampling cannot resolve in some event: why, and in how many events.

    Measured and simulated speeds share the measured time stamps, so the measured reasons hold
    for both (:func:`app.analysis.metrics.ripple_metrics`).
    """
    first: dict[str, str] = {}
    count: dict[str, int] = {}
    for c in comparisons:
        for k, why in c.measured.resolution.items():
            first.setdefault(k, why)
            count[k] = count.get(k, 0) + 1
    return {k: f"{first[k]} ({count[k]} of {len(comparisons)} events)" for k in first}
