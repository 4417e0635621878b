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

:func:`sample_period` is the one rule for a channel's period that the analysis (whole-log time
base) and the diagnosis (noise floor, re-timing, fit bounds) share: the mean spacing of a
stream that comes in bursts (median below ``BURST_MEDIAN_RATIO`` of the mean), else the median
of the spacings that are not drop-outs, so a few lost frames do not lengthen the period of a
regular stream. The two commands gave 21 ms and 4 ms on the same bursty log before.

A logger whose stamps are off by a large part of a shuffle period (a gateway holding frames for
tens of milliseconds) is re-timed from a timer the ECU writes into the speed's own message, the
signal map's ``time_base`` (:func:`timer_times`).
"""

from __future__ import annotations

import numpy as np

from app.analysis.series import FloatArray
from app.errors import InsufficientDataError
from app.signals.sampling import BURST_MEDIAN_RATIO, Spacing, spacing

__all__ = ["Spacing", "sample_period", "spacing", "uniform_by_timestamps"]

DROPOUT_PERIODS = 1.5  # a spacing longer than this many median spacings is a drop-out


def sample_period(t: FloatArray) -> float:
    """The sampling period (s) of time stamps ``t`` (see the module docstring).

    Raises InsufficientDataError with fewer than two distinct time stamps.
    """
    d = np.diff(np.asarray(t, dtype=np.float64))
    d = d[d > 0]
    if d.size == 0:
        raise InsufficientDataError("the channel has fewer than two distinct timestamps")
    mean, first = float(np.mean(d)), float(np.median(d))
    if first < BURST_MEDIAN_RATIO * mean:
        return mean
    single = d[d < DROPOUT_PERIODS * first]
    return float(np.median(single)) if single.size else first


def unwrap_timer(values: FloatArray) -> FloatArray:
    """A timer or counter (s) without its wrap-arounds: the modulus is taken from the data (its range plus
    one step), and every fall by more than half of it adds one modulus."""
    v = np.asarray(values, dtype=np.float64)
    d = np.diff(v)
    up = d[d > 0]
    if not up.size:
        return v
    modulus = float(np.ptp(v)) + float(np.median(up))
    wraps = np.concatenate(([0.0], np.cumsum(d < -0.5 * modulus)))
    return np.asarray(v + modulus * wraps, dtype=np.float64)


def timer_times(t_log: FloatArray, timer: FloatArray) -> FloatArray:
    """Sample times (s, on the log's clock) from an ECU timer read with each sample (``timer``, s, may wrap).

    The timer is unwrapped and put on the log's clock by a straight line through ``t_log - timer`` (the
    two clocks' offset and rate difference), fitted again to the frames within ``3`` robust sigmas of the
    first line: frames a logger held back are late by tens of milliseconds and would tilt it.
    """
    t = np.asarray(t_log, dtype=np.float64)
    tt = unwrap_timer(timer)
    if t.size < 3 or np.ptp(tt) <= 0:
        return t
    x, gap = tt - tt[0], t - tt
    coef = np.polyfit(x, gap, 1)
    for _ in range(2):
        resid = gap - np.polyval(coef, x)
        dev = np.abs(resid - np.median(resid))
        on_time = dev <= 3.0 * 1.4826 * float(np.median(dev)) + 1e-9
        if on_time.sum() < 3:
            break
        coef = np.polyfit(x[on_time], gap[on_time], 1)
    return np.asarray(tt + np.polyval(coef, x), dtype=np.float64)


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
