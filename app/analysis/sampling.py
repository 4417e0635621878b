"""Sampling adequacy: the real spacing of a channel's time stamps and what it can resolve.

CAN channels are rarely uniform. An inverter that sends its frames in bursts (2-3 frames
1-5 ms apart, a burst every 40-60 ms) has a *median* spacing of a few ms but delivers one
new value every ~20 ms on average: the median describes the bursts, not the information
rate. Everything that needs "the sample period" (noise floor, spectral estimates, the time
resolution of a metric) therefore uses the **mean** spacing ``span / (n - 1)`` and checks
the **maximum** spacing; a stream that comes in bursts or with holes (the rule of
:func:`app.signals.sampling.spacing`, the same one the decode report applies per message) is
resampled onto a uniform grid at its mean spacing by linear interpolation between its actual
time stamps before the ripple metrics are computed.
"""

from __future__ import annotations

import numpy as np

from app.analysis.series import FloatArray
from app.signals.sampling import Spacing, spacing

__all__ = ["Spacing", "mean_period", "spacing", "uniform_by_timestamps"]


def mean_period(t: FloatArray) -> float:
    """Mean sample period (s) of time stamps ``t``; NaN for fewer than two samples."""
    return spacing(t).mean_s


def uniform_by_timestamps(t: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, Spacing]:
    """``(t, y)`` on a uniform grid at its mean spacing when bursty, else unchanged.

    Linear interpolation between the actual time stamps; samples sharing a time stamp are
    averaged first. Returns the grid, the values and the spacing of the *original* stamps.
    """
    sp = spacing(t)
    if not sp.bursty or not np.isfinite(sp.mean_s) or sp.mean_s <= 0:
        return t, y, sp
    tu, inv = np.unique(t, return_inverse=True)
    yu = np.bincount(inv, weights=y) / np.bincount(inv)
    n = int(np.floor((tu[-1] - tu[0]) / sp.mean_s + 1e-9)) + 1
    grid = tu[0] + sp.mean_s * np.arange(n, dtype=np.float64)
    return grid, np.interp(grid, tu, yu), sp
