"""How a signal was sampled: spacing statistics and whether the samples come in bursts.

Loggers and gateways often forward a message in bursts: several frames within a millisecond,
then nothing for tens of milliseconds (a 48 Hz inverter message logged as 1 ms, 1 ms, 59 ms).
The median spacing of such a stream is far below its mean, so a sampling period taken from
the median overstates the resolution several times. The period to use for such a signal is
the mean spacing (samples per second), and time-based steps should use the actual time
stamps, never ``n * median``. :func:`spacing` measures a signal's time stamps;
:func:`burst_reason` is the rule shared with the per-ID statistics of a decode report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.serial import Serial

BURST_MEDIAN_RATIO = 0.5  # median spacing below this fraction of the mean: bursts
GAP_MEANS = 5.0  # a gap longer than this many mean spacings: the stream has holes
MIN_INTERVALS = 10  # fewer spacings than this are not judged


@dataclass(frozen=True, slots=True)
class Spacing(Serial):
    """Spacing of consecutive samples in ms (None with fewer than two samples).

    ``bursty`` is True when the median is far below the mean or a gap spans several means;
    ``reason`` says which, in words. ``period_s`` is the sampling period to use: the mean.
    """

    samples: int
    mean_ms: float | None
    median_ms: float | None
    p95_ms: float | None
    max_ms: float | None
    bursty: bool = False
    reason: str = ""

    @property
    def period_s(self) -> float | None:
        """The mean spacing in s: the period a bursty stream really delivers."""
        return None if self.mean_ms is None else self.mean_ms / 1000.0

    @property
    def rate_hz(self) -> float | None:
        return None if not self.mean_ms else 1000.0 / self.mean_ms

    @property
    def mean_s(self) -> float:
        """The mean spacing in s, NaN with fewer than two samples (for arithmetic on the period)."""
        return _seconds(self.mean_ms)

    @property
    def median_s(self) -> float:
        return _seconds(self.median_ms)

    @property
    def max_s(self) -> float:
        return _seconds(self.max_ms)


def _seconds(ms: float | None) -> float:
    return float("nan") if ms is None else ms / 1000.0


def burst_reason(intervals: int, mean_ms: float | None, median_ms: float | None, max_ms: float | None) -> str:
    """Why a stream with these spacing statistics is bursty, or ``""`` when it is not (or too short to say)."""
    if intervals < MIN_INTERVALS or not mean_ms or mean_ms <= 0 or median_ms is None or max_ms is None:
        return ""
    if median_ms < BURST_MEDIAN_RATIO * mean_ms:
        return (f"median spacing {median_ms:.3g} ms is {median_ms / mean_ms:.2f} of the mean {mean_ms:.3g} ms: "
                "samples come in bursts; use the mean as the period")
    if max_ms > GAP_MEANS * mean_ms:
        return f"gaps up to {max_ms:.4g} ms, {max_ms / mean_ms:.0f} times the mean spacing {mean_ms:.3g} ms"
    return ""


_MEDIAN_P95 = np.array([50.0, 95.0]) / 100


def median_p95(x: npt.NDArray[np.float64]) -> tuple[float, float]:
    """``np.percentile(x, [50, 95])`` (linear interpolation), bit for bit, for a 1-D float array.

    The same order statistics and interpolation as numpy's, by one partition of a copy;
    ``np.percentile`` itself loads ``numpy.ma`` on its first call, a tenth of a command-line
    decode's own work. Arrays holding NaN go to ``np.percentile``.
    """
    n = int(x.size)
    virtual = (n - 1) * _MEDIAN_P95
    lower = np.floor(virtual)
    upper = lower + 1
    above = virtual >= n - 1
    lower[above], upper[above] = -1, -1
    lo_i, hi_i = lower.astype(np.intp), upper.astype(np.intp)
    kth = sorted({0, n - 1, *(int(i) % n for i in (*lo_i.tolist(), *hi_i.tolist()))})
    part = np.partition(x, kth)
    if np.isnan(part[-1]):
        return tuple(float(v) for v in np.percentile(x, [50.0, 95.0]))  # type: ignore[return-value]
    a, b = part[lo_i], part[hi_i]
    gamma = virtual - lo_i
    diff = b - a
    out = a + diff * gamma
    np.subtract(b, diff * (1 - gamma), out=out, where=gamma >= 0.5)
    return float(out[0]), float(out[1])


def spacing(t_s: npt.ArrayLike) -> Spacing:
    """Spacing statistics of time stamps ``t_s`` (s, in order); exact (numpy median and 95th percentile)."""
    t = np.asarray(t_s, dtype=np.float64)
    n = int(t.size)
    if n < 2:
        return Spacing(n, None, None, None, None)
    dt_ms = np.diff(t) * 1000.0
    mean = float((t[-1] - t[0]) * 1000.0 / (n - 1))
    median, p95 = median_p95(dt_ms)
    top = float(dt_ms.max())
    reason = burst_reason(n - 1, mean, median, top)
    return Spacing(n, mean, median, p95, top, bool(reason), reason)
