"""WHERE the gap lies: residual energy per event, per phase and per frequency band.

Phases come from the calibrated baseline simulation's gap states (the data alone cannot see a
~20 ms gap-open phase at 100 Hz)::

    pre_event     before the lash opens at the reversal (or before the torque crossing when no gap opens)
    gap_traverse  from that loss of load to the impact that first closes every gap again
    impact        the first 50 ms after that closing
    oscillation   the next 550 ms (about four shuffle periods)
    steady        the rest of the window

Bands: 0-2 Hz (road load, trends), 2-12 Hz (shuffle), 12-25 Hz (mounts, housing), above 25 Hz
(sensor, sampling). Band energy is the Parseval share of the residual resampled to the nominal
sample period; residual-torque coherence per band is estimated with the events as segments
(``|sum_e R_e T_e*|^2 / (sum_e |R_e|^2 sum_e |T_e|^2)``), so it is 1 only if the residual is a
consistent linear response to the torque.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.forward import DiagEvent, Prediction
from app.analysis.diagnosis.score import BANDS, PHASES

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

IMPACT_S = 0.05
OSCILLATION_S = 0.55
_SEARCH_S = (0.15, 0.4)  # the reversal's gap opens/closes within t_event - 0.15 s .. t_event + 0.4 s
# Shortest open stretch taken for a lash traverse. The free run across the lash lasts 5-40 ms over the
# backlash prior (about 20 ms nominal); what else opens near a reversal is shorter: rebounds after the
# impact (1-2 ms of separation after 0.1-2 ms of contact) and the chatter of a lash touched by the shuffle.
MIN_TRAVERSE_S = 0.003
# Speed samples a lash traverse must span (median event) for the log to show where the lash sits (``backlash``)
# or how large it is (identification): a traverse that falls between two samples is a small phase shift that trades
# with the damping and the contact law's model form (the independent generator's low-mode chain car: 27-31 ms, 1.4-1.6
# samples at 50 Hz, its lash fitted 50-70 % off; its paper car at 100 Hz: 38 ms, within 1 %)
MIN_TRAVERSE_SAMPLES = 2


@dataclass(frozen=True)
class PhaseTimes:
    """Phase boundaries of one event (s); ``t_open == t_close`` when no gap opened."""

    t_open: float
    t_close: float
    resolved_samples: int  # measured samples inside the gap-traverse phase

    def labels(self, t: FloatArray) -> IntArray:
        """(n,) index into :data:`PHASES` for each time."""
        lab = np.full(t.shape, 4, dtype=np.int64)
        lab[t < self.t_close + IMPACT_S + OSCILLATION_S] = 3
        lab[t < self.t_close + IMPACT_S] = 2
        lab[t < self.t_close] = 1
        lab[t < self.t_open] = 0
        return lab


def open_runs(g: BoolArray) -> IntArray:
    """(k, 2) ``[first, stop)`` sample indices of the contiguous ``True`` stretches of ``g``, in time order."""
    d = np.diff(np.concatenate(([0], g.astype(np.int8), [0])))
    return np.column_stack((np.flatnonzero(d == 1), np.flatnonzero(d == -1))).astype(np.int64)


def phase_times(ev: DiagEvent, pred: Prediction) -> PhaseTimes:
    """Phase boundaries from the predicted gap states around the event's torque crossing.

    The lash traverse is the first open stretch near the crossing that lasts at least
    :data:`MIN_TRAVERSE_S`: it starts with the loss of load and ends at the impact. Open stretches
    after it -- rebounds of the impact, a lash reopened by the shuffle -- belong to the impact and
    oscillation phases. Contacts are not bridged: a rebound follows a contact of 0.1-2 ms, as short as
    any contact inside the traverse, so bridging would move the impact onto the last rebound. (Contacts
    shorter than the simulator's output step do not show in the mask and are bridged by it.) When no
    stretch is that long, the longest one (the first of equals) is taken.
    """
    t, g = pred.t_fine, pred.gap_open
    if g is None or not g.any():
        return PhaseTimes(ev.t_event, ev.t_event, 0)
    near = (t >= ev.t_event - _SEARCH_S[0]) & (t <= ev.t_event + _SEARCH_S[1])
    runs = open_runs(g & near)
    if runs.shape[0] == 0:
        return PhaseTimes(ev.t_event, ev.t_event, 0)
    # a stretch's duration counts from its first open sample to the first closed one
    stop = np.minimum(runs[:, 1], t.size - 1)
    length = t[stop] - t[runs[:, 0]]
    long_enough = np.flatnonzero(length >= MIN_TRAVERSE_S - 1e-9)
    k = int(long_enough[0]) if long_enough.size else int(np.argmax(length))
    t_open, t_close = float(t[runs[k, 0]]), float(t[stop[k]])
    n_res = int(np.sum((ev.speed_t >= t_open) & (ev.speed_t < t_close)))
    return PhaseTimes(t_open, t_close, n_res)


def phase_chi2(r: FloatArray, labels: IntArray) -> tuple[dict[str, float], dict[str, int]]:
    """Weighted residual energy and sample count per phase."""
    chi = {p: float(np.sum(r[labels == i] ** 2)) for i, p in enumerate(PHASES)}
    cnt = {p: int(np.sum(labels == i)) for i, p in enumerate(PHASES)}
    return chi, cnt


def uniform(ev: DiagEvent, y: FloatArray, period: float) -> tuple[FloatArray, FloatArray]:
    """``y`` (at the speed sample times) linearly resampled onto the nominal grid of the window."""
    n = max(int(np.floor((ev.speed_t[-1] - ev.speed_t[0]) / period)) + 1, 2)
    tu = ev.speed_t[0] + period * np.arange(n)
    return tu, np.asarray(np.interp(tu, ev.speed_t, y), dtype=np.float64)


def band_energy(y: FloatArray, period: float) -> dict[str, float]:
    """Parseval split of ``sum(y**2)`` (rpm^2) into :data:`BANDS` (uniform samples ``period`` apart)."""
    n = y.size
    spec = np.abs(np.fft.rfft(y)) ** 2 / n
    spec[1:] *= 2.0
    if n % 2 == 0:
        spec[-1] /= 2.0
    f = np.fft.rfftfreq(n, period)
    return {name: float(spec[(f >= lo) & (f < hi)].sum()) for name, lo, hi in BANDS}


def coherence_by_band(residuals: Sequence[FloatArray], torques: Sequence[FloatArray],
                      period: float) -> dict[str, float]:
    """Magnitude-squared residual-torque coherence per band, events as segments (common length)."""
    if len(residuals) < 2:
        return {name: float("nan") for name, _, _ in BANDS}
    n = min(r.size for r in residuals)
    win = np.hanning(n)
    sxy = np.zeros(n // 2 + 1, complex)
    sxx = np.zeros(n // 2 + 1)
    syy = np.zeros(n // 2 + 1)
    for r, q in zip(residuals, torques, strict=True):
        R = np.fft.rfft((r[:n] - r[:n].mean()) * win)
        T = np.fft.rfft((q[:n] - q[:n].mean()) * win)
        sxy += R * np.conj(T)
        sxx += np.abs(R) ** 2
        syy += np.abs(T) ** 2
    coh = np.abs(sxy) ** 2 / np.maximum(sxx * syy, 1e-300)
    f = np.fft.rfftfreq(n, period)
    out = {}
    for name, lo, hi in BANDS:
        m = (f >= max(lo, 1e-9)) & (f < hi)
        out[name] = float(np.mean(coh[m])) if m.any() else float("nan")
    return out


def residual_torque_lag(residuals: Sequence[FloatArray], torques: Sequence[FloatArray], period: float,
                        max_lag_s: float = 0.2) -> tuple[float, float]:
    """Lag (s) and normalised value of the peak cross-correlation of the residual with the torque rate.

    A peak at positive lag means the residual follows torque changes: a delay or missing dynamics.
    """
    if not residuals:
        return float("nan"), float("nan")
    m = round(max_lag_s / period)
    acc = np.zeros(2 * m + 1)
    norm_r = norm_q = 0.0
    for r, q in zip(residuals, torques, strict=True):
        dq = np.gradient(q)
        rr = r - r.mean()
        full = np.correlate(rr, dq, mode="full")  # index n-1 is lag 0; positive lag: r after dq
        mid = rr.size - 1
        lo, hi = max(mid - m, 0), min(mid + m + 1, full.size)
        acc[lo - (mid - m):hi - (mid - m)] += full[lo:hi]
        norm_r += float(np.dot(rr, rr))
        norm_q += float(np.dot(dq, dq))
    acc /= max(np.sqrt(norm_r * norm_q), 1e-300)
    k = int(np.argmax(np.abs(acc)))
    return float((k - m) * period), float(acc[k])
