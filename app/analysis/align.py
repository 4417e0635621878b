"""Alignment of measured and simulated series: common time base, time offset, downsampling.

Conventions: a *lag* ``L`` (s) means ``target(t) ~ reference(t - L)``: positive when the
target comes later. The simulator is driven by the logged torque with no delay, so the
lag of the measured speed behind the simulated speed is the torque-to-speed time offset
of the log (CAN scheduling, inverter filtering, actuator delay).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.signal import correlate

from app.analysis.downsample import downsample
from app.analysis.series import FloatArray, parabolic_vertex
from app.errors import InputError, InsufficientDataError
from app.signals import Signal


@dataclass(frozen=True)
class OffsetEstimate:
    lag_s: float  # target lags reference by this much (s); 0.0 when not estimable
    correlation: float  # normalised cross-correlation at the lag, in [-1, 1]; NaN when not estimable
    samples: int  # samples that entered the estimate
    applied: bool = True  # False: too weakly correlated to shift the simulation by (lag_s kept for reference)


def common_time_base(t0: float, t1: float, dt: float) -> FloatArray:
    """Uniform grid ``t0, t0 + dt, ... <= t1`` (s), shape (n,)."""
    if not dt > 0 or not np.isfinite(dt):
        raise InputError(f"time base step dt = {dt!r} s must be a positive finite number")
    if not t1 >= t0:
        raise InsufficientDataError(f"no common time span: {t0:.3f} s to {t1:.3f} s")
    n = int(np.floor((t1 - t0) / dt + 1e-9)) + 1
    return t0 + dt * np.arange(n, dtype=np.float64)


def overlap(signals: Sequence[Signal]) -> tuple[float, float]:
    """Time span covered by every signal."""
    if not signals or any(len(s) == 0 for s in signals):
        raise InsufficientDataError("cannot align: a signal has no samples")
    return max(float(s.t[0]) for s in signals), min(float(s.t[-1]) for s in signals)


def resample_onto(signals: Mapping[str, Signal], t: FloatArray) -> dict[str, FloatArray]:
    """Each signal's values on the grid ``t`` with its own interpolation mode (NaN outside its span)."""
    return {name: sig.at(t) for name, sig in signals.items()}


def _high_pass(y: FloatArray) -> FloatArray:
    # The first difference keeps the ripple (where timing is visible) and drops offsets and slow drift.
    d = np.diff(y)
    return np.where(np.isfinite(d), d, 0.0)


def estimate_lag(
    reference: FloatArray, target: FloatArray, dt: float, max_lag_s: float,
    mask: npt.NDArray[np.bool_] | None = None,
) -> OffsetEstimate:
    """Lag of ``target`` behind ``reference`` on a common uniform grid of step ``dt``.

    The normalised cross-correlation of the first differences is evaluated for every
    whole-sample lag within ``±max_lag_s`` over the samples selected by ``mask`` (e.g.
    the event windows) and refined to sub-sample resolution with a parabola.
    """
    if reference.shape != target.shape:
        raise InputError(f"reference {reference.shape} and target {target.shape} must share one time base")
    a, b = _high_pass(reference), _high_pass(target)
    sel = np.ones(a.size, bool) if mask is None else np.asarray(mask[1:], bool)
    kmax = int(np.floor(max_lag_s / dt))
    n = a.size
    if n <= 2 * kmax + 2 or sel.sum() < 4:
        return OffsetEstimate(0.0, float("nan"), int(sel.sum()))
    core = np.zeros(n, bool)
    core[kmax:n - kmax] = True
    core &= sel
    am = np.where(core, a, 0.0)
    # every lag at once: FFT cross-correlations of the masked reference with the target (and its energy)
    num = correlate(b, am, mode="full", method="fft")[n - 1 - kmax:n + kmax]
    energy_b = correlate(b * b, core.astype(np.float64), mode="full", method="fft")[n - 1 - kmax:n + kmax]
    den = np.sqrt(np.maximum(float(np.dot(am, am)) * energy_b, 0.0))
    lags = np.arange(-kmax, kmax + 1)
    corr = np.where(den > 0, num / np.where(den > 0, den, 1.0), 0.0)
    best = int(np.argmax(corr))
    off, val = parabolic_vertex(corr, best)
    return OffsetEstimate(float((lags[best] + off) * dt), float(np.clip(val, -1.0, 1.0)), int(core.sum()))


def shift(sig: Signal, lag_s: float) -> Signal:
    """The signal delayed by ``lag_s`` (its samples happen ``lag_s`` later)."""
    return Signal(sig.name, sig.t + lag_s, sig.values, sig.unit, sig.interp, sig.labels)


def downsample_minmax(
    t: FloatArray, columns: Mapping[str, FloatArray], max_points: int
) -> tuple[FloatArray, dict[str, FloatArray]]:
    """At most ``max_points`` rows that keep every bucket's minimum and maximum of every column.

    The rows are split into equal buckets; in each, the rows holding each column's min and
    max are kept (plus the first and last row), so peaks and valleys survive for plotting.
    NaN values are ignored when choosing the rows. Returns the kept times and columns.
    (:func:`app.analysis.downsample.downsample` also offers LTTB.)
    """
    return downsample(t, columns, max_points, "minmax")
