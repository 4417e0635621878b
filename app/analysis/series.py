"""Small array helpers shared by the analysis modules (no I/O)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from app.signals import Signal

FloatArray = npt.NDArray[np.float64]


def finite_signal(sig: Signal) -> Signal:
    """The signal without its NaN/inf samples (CAN "not available" values)."""
    keep = np.isfinite(sig.values)
    if bool(keep.all()):
        return sig
    return Signal(sig.name, sig.t[keep], sig.values[keep], sig.unit, sig.interp, sig.labels)


def median_in(sig: Signal, t0: float, t1: float) -> float:
    """Median of the finite samples with ``t0 <= t <= t1``; NaN when there are none."""
    m = (sig.t >= t0) & (sig.t <= t1) & np.isfinite(sig.values)
    return float(np.median(sig.values[m])) if m.any() else float("nan")


def median_period(t: FloatArray) -> float:
    """Median sample period in s (NaN for fewer than two samples)."""
    return float(np.median(np.diff(t))) if t.size > 1 else float("nan")


def parabolic_vertex(y: FloatArray, i: int) -> tuple[float, float]:
    """Sub-sample offset and value of the extremum at index ``i`` from a 3-point parabola.

    Returns ``(offset in samples, value)``; the offset is in [-0.5, 0.5] and ``(0, y[i])``
    at the edges or on a flat top.
    """
    if i <= 0 or i >= y.size - 1:
        return 0.0, float(y[i])
    a, b, c = float(y[i - 1]), float(y[i]), float(y[i + 1])
    den = a - 2.0 * b + c
    if den == 0.0 or not np.isfinite(den):
        return 0.0, b
    off = float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))
    return off, b - 0.25 * (a - c) * off


def noise_rms(y: FloatArray) -> float:
    """Model-free white-noise RMS from second differences (``std(d2) / sqrt(6)``)."""
    y = y[np.isfinite(y)]
    if y.size < 5:
        return 0.0
    return float(np.std(np.diff(y, 2)) / np.sqrt(6.0))


def moving_mean(t: FloatArray, y: FloatArray, window_s: float) -> FloatArray:
    """Mean of ``y`` over ``[t_i, t_i + window_s]`` for every sample ``i`` (finite ``y``, increasing ``t``)."""
    c = np.concatenate(([0.0], np.cumsum(y)))
    i = np.arange(t.size)
    hi = np.searchsorted(t, t + window_s, side="right")
    return np.asarray((c[hi] - c[i]) / (hi - i), dtype=np.float64)


def quantisation_step(values: FloatArray) -> float:
    """Smallest step (the channel's unit) between distinct sample values, robust to float round-off; 0 if none."""
    v = np.unique(np.round(np.asarray(values, dtype=np.float64), 9))
    if v.size < 2:
        return 0.0
    steps = np.diff(v)
    steps = steps[steps > 1e-9]
    if steps.size == 0:
        return 0.0
    q = float(steps.min())
    # only a quantiser if the other steps are (nearly) integer multiples of the smallest one
    ratio = steps[: min(steps.size, 2000)] / q
    return q if float(np.median(np.abs(ratio - np.round(ratio)))) < 0.05 else 0.0
