"""Ripple metrics (pure numpy). Each is defined exactly here and in docs/simulation.md.

All take a uniform or irregular time grid ``t`` (s, increasing) and speeds in rpm; the
optional window ``[t_start, t_end]`` (s) restricts the samples considered.
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike, NDArray

F64 = NDArray[np.float64]


def _window(t: ArrayLike, y: ArrayLike, t_start: float | None, t_end: float | None) -> tuple[F64, F64]:
    tt = np.asarray(t, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    if tt.shape != yy.shape or tt.ndim != 1:
        raise ValueError(f"t and y must be 1-D of equal length, got {tt.shape} and {yy.shape}")
    keep = np.ones(tt.size, dtype=bool)
    if t_start is not None:
        keep &= tt >= t_start
    if t_end is not None:
        keep &= tt <= t_end
    return tt[keep], yy[keep]


def peak_to_valley(t: ArrayLike, speed_rpm: ArrayLike, t_start: float | None = None,
                   t_end: float | None = None) -> float:
    """Largest fall from a peak to the *adjacent* (next) valley, rpm.

    The paper's "speed fluctuation between a peak and the adjacent valley": over the window,
    find the local extrema of the speed (plateaus count once, the window ends count as
    extrema) and return ``max(y[peak_k] - y[valley after peak_k])``; 0 when the speed never
    falls. A steady rise or fall contributes nothing, unlike max - min.
    """
    _, y = _window(t, speed_rpm, t_start, t_end)
    if y.size < 2:
        return 0.0
    d = np.diff(y)
    keep = d != 0
    if not keep.any():
        return 0.0
    # indices where the slope sign changes: extrema of the plateau-free sequence
    idx = np.concatenate(([0], np.flatnonzero(keep) + 1))
    z = y[idx]
    s = np.sign(np.diff(z))
    turn = np.flatnonzero(s[1:] != s[:-1]) + 1
    ext = np.concatenate(([0], turn, [z.size - 1]))
    vals = z[ext]
    drops = vals[:-1] - vals[1:]
    return float(max(0.0, drops.max())) if drops.size else 0.0


def peak_to_peak(t: ArrayLike, y: ArrayLike, t_start: float | None = None, t_end: float | None = None) -> float:
    """``max(y) - min(y)`` over the window."""
    _, yy = _window(t, y, t_start, t_end)
    return float(yy.max() - yy.min()) if yy.size else 0.0


def impact_induced_fluctuation(t: ArrayLike, speed_with_gaps: ArrayLike, speed_without_gaps: ArrayLike,
                               t_start: float | None = None, t_end: float | None = None) -> float:
    """Peak-to-peak (rpm) of the impact-induced response ``n_gaps(t) - n_no_gaps(t)``.

    Both speeds come from the same torque and initial speed; the difference removes the
    ordinary linear shuffle response to the torque change, which no gap removal can touch,
    leaving what the gaps add: the free run-up while they are open and the ring-down after
    the impact.
    """
    a = np.asarray(speed_with_gaps, dtype=np.float64)
    b = np.asarray(speed_without_gaps, dtype=np.float64)
    if a.shape != b.shape:
        raise ValueError(f"speed arrays differ in shape: {a.shape} vs {b.shape}")
    return peak_to_peak(t, a - b, t_start, t_end)


def unloaded_intervals(
    gap_events: Iterable[tuple[str, float, float]], t_end: float = math.inf
) -> list[tuple[float, float]]:
    """Maximal intervals in which at least one gap is open (the motor runs unloaded), s.

    ``gap_events`` are ``(gap, t_open, t_close)`` as in ``SimResult.gap_events``; an interval
    still open at the end closes at ``t_end``.
    """
    spans = sorted((a, b if math.isfinite(b) else t_end) for _, a, b in gap_events)
    merged: list[tuple[float, float]] = []
    for a, b in spans:
        if merged and a <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], b))
        else:
            merged.append((a, b))
    return merged


def unloaded_time(gap_events: Iterable[tuple[str, float, float]], t_start: float = -math.inf,
                  t_end: float = math.inf) -> float:
    """Length (s) of the first unloaded interval starting at or after ``t_start``.

    The paper's "time from the disengagement of the first set of gaps to the closing of all
    gaps": from the first gap opening to the instant every gap is closed again. 0 if no gap
    opens in ``[t_start, t_end]``.
    """
    for a, b in unloaded_intervals(gap_events, t_end):
        if t_start <= a <= t_end:
            return b - a
    return 0.0
