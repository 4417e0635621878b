"""Sampling adequacy: the real spacing of a channel's time stamps and what it can resolve.

CAN channels are rarely uniform. An inverter that sends its frames in bursts (2-3 frames
1-5 ms apart, a burst every 40-60 ms) has a *median* spacing of a few ms but delivers one
new value every ~20 ms on average: the median describes the bursts, not the information
rate. Everything that needs "the sample period" (noise floor, spectral estimates, the time
resolution of a metric) therefore uses the **mean** spacing ``span / (n - 1)`` and checks
the **maximum** spacing; a stream whose spacings vary a lot (coefficient of variation above
``BURSTY_CV``) is resampled onto a uniform grid at its mean spacing by linear interpolation
between its actual time stamps before the ripple metrics are computed.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from app.analysis.series import FloatArray

BURSTY_CV = 0.35  # spacing std / mean above this: bursty (a jittered periodic CAN message stays below 0.1)


@dataclass(frozen=True)
class Spacing:
    """Time-stamp spacing of one channel, s (NaN for fewer than two samples)."""

    samples: int
    mean_s: float  # (t_last - t_first) / (samples - 1): the information rate
    max_s: float  # the longest gap
    median_s: float  # what a burst looks like; not a sample period for bursty streams
    cv: float  # std / mean of the spacings
    bursty: bool

    def to_dict(self) -> dict[str, object]:
        return asdict(self)


def spacing(t: FloatArray) -> Spacing:
    """Mean, maximum and median spacing of increasing time stamps ``t`` (s), shape (n,)."""
    n = int(t.size)
    if n < 2:
        nan = float("nan")
        return Spacing(n, nan, nan, nan, nan, False)
    d = np.diff(t)
    mean = float((t[-1] - t[0]) / (n - 1))
    cv = float(np.std(d) / mean) if mean > 0 else float("nan")
    return Spacing(n, mean, float(d.max()), float(np.median(d)), cv, bool(cv > BURSTY_CV))


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
