"""From decoded signals and detected events to the diagnosis' event data.

Checks the channels (a missing one raises :class:`~app.errors.MissingSignalError` naming it),
puts frames a buffering logger wrote back-to-back back at their sampling times (:mod:`.retime`),
estimates the model-free noise floor from the speed samples *outside* every event window, and
cuts each included event to the window the diagnosis simulates and scores: ``pre_s`` before the
torque crossing to ``post_s`` after it (inside the event's own window). Each window's simulation
starts earlier, at its warm start (:func:`warm_start`), so that no event is scored from a
fictitious rest state.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.forward import MARGIN_S, DiagEvent, FloatArray
from app.analysis.diagnosis.noise import (
    NoiseFloor,
    estimate_noise_floor,
    measured_slope,
    white_noise_sigma,
)
from app.analysis.diagnosis.retime import Retimed, retime_bursts
from app.analysis.events import SPEED, TORQUE, Event, EventParams
from app.analysis.sampling import sample_period
from app.analysis.series import quantisation_step
from app.errors import InsufficientDataError, MissingSignalError
from app.signals import SignalSet

REQUIRED = (TORQUE, SPEED)

# Event detection for the diagnosis: a window cut short by the next reversal is kept when 0.3 s
# (the impact and one to two shuffle periods) remain. The ripple metrics need 0.6 s, the diagnosis
# does not: its windows are simulated through the next reversal's torque (warm starts, clusters),
# and with reversals 0.7-1.1 s apart the 0.6 s rule left a quarter of the events.
DIAGNOSIS_EVENTS = EventParams(min_post_s=0.3)


@dataclass(frozen=True)
class WindowParams:
    pre_s: float = 0.3  # simulated before the torque crossing (the initial-condition anchor needs a few samples)
    post_s: float = 1.0  # after it: impact, about six shuffle periods, and some steady response
    anchor_end_s: float = 0.08  # anchor on samples more than this before the crossing (gaps open near it)
    torque_margin_s: float = 0.1  # torque kept beyond the window so the time-offset fit can shift it
    min_samples: int = 20
    # a low-rate logger (20-25 Hz) holds 15-19 speed samples in a window cut short by the next event: such a window
    # is used when it has at least this many samples and reaches this far past the crossing (two periods of a 5 Hz
    # shuffle), which a 100 Hz or faster log meets with 20 samples anyway
    min_samples_low_rate: int = 12
    min_post_cover_s: float = 0.4
    settle_s: float = 2.5  # torque steady this long: the shuffle of the last change has decayed (quasi-static)
    settle_tol_nm: float = 4.0  # "steady": torque range within the settle time at most this (N m)
    max_warm_s: float = 4.0  # the warm-up reaches back at most this far before the window


def enough_samples(t: FloatArray, t_cross: float, p: WindowParams) -> bool:
    """Whether a window's speed stamps ``t`` are enough to fit: ``min_samples`` of them, or at a low rate
    ``min_samples_low_rate`` reaching ``min_post_cover_s`` past the crossing."""
    if t.size >= p.min_samples:
        return True
    return t.size >= p.min_samples_low_rate and float(t[-1]) - t_cross >= p.min_post_cover_s


def warm_start(tq_t: FloatArray, tq_v: FloatArray, t_window: float, p: WindowParams) -> float:
    """Start of the simulation for a window starting at ``t_window`` (s).

    The latest time at or before ``t_window`` at which the state is quasi-static -- the torque
    within ``settle_tol_nm`` for the ``settle_s`` before it, so whatever shuffle an earlier change
    set off has died out (the paper vehicle's shuffle after a full 140 N m step falls from 285 rpm
    to under 2 rpm in 2.5 s) -- searched back to ``max_warm_s`` before the window, or the log
    start. When there is none, the run starts ``max_warm_s`` early: the state there is not
    quasi-static, but its error has then decayed for longer than the settle time by the window.
    """
    lo = max(float(tq_t[0]), t_window - p.max_warm_s)
    near = (tq_t >= lo - p.settle_s) & (tq_t <= t_window)
    tt, vv = tq_t[near], tq_v[near]
    first = np.searchsorted(tt, tt - p.settle_s)  # first sample of the settle time before each sample
    # the samples that may end a settle time, searched back from the last: from lo on, with a whole settle time of
    # log before them (the last run of such samples: all of them where the times increase)
    ok = (tt >= lo) & (tt - p.settle_s >= tq_t[0])
    bad = np.flatnonzero(~ok)
    cand = np.arange(bad[-1] + 1 if bad.size else 0, tt.size)
    if cand.size:
        steady = np.flatnonzero(_window_ptp(vv, first[cand], cand) <= p.settle_tol_nm)
        if steady.size:
            j = int(cand[steady[-1]])
            return t_window if j == tt.size - 1 else float(tt[j])
    return lo


def _window_ptp(v: FloatArray, a: npt.NDArray[np.intp], b: npt.NDArray[np.intp]) -> FloatArray:
    """``np.ptp(v[a_i:b_i + 1])`` for every pair (``a_i <= b_i``) from a sparse table of maxima and minima: exact,
    NaN where the window holds one, O(n log n) instead of one pass per window."""
    out = np.empty(a.size)
    if not a.size:
        return out
    level = np.floor(np.log2(b - a + 1)).astype(np.intp)
    hi, lo = v.astype(np.float64), v.astype(np.float64)
    for k in range(int(level.max()) + 1):
        if k:
            w = 1 << (k - 1)
            hi, lo = np.maximum(hi[:-w], hi[w:]), np.minimum(lo[:-w], lo[w:])  # windows of 2^k from each start
        at = level == k
        if at.any():
            end = b[at] - (1 << k) + 1
            out[at] = np.maximum(hi[a[at]], hi[end]) - np.minimum(lo[a[at]], lo[end])
    return out


def speed_at(sp_t: FloatArray, sp_v: FloatArray, t: float, half_s: float = 0.03) -> float:
    """Measured speed at ``t`` (rpm): a line through the samples within ``half_s`` of it."""
    m = np.abs(sp_t - t) <= half_s
    if int(m.sum()) < 3:
        return float(np.interp(t, sp_t, sp_v))
    c = np.polyfit(sp_t[m] - t, sp_v[m], 1)
    return float(c[1])


def require_channels(signals: SignalSet) -> None:
    missing = [name for name in REQUIRED if name not in signals or len(signals[name]) == 0]
    if missing:
        raise MissingSignalError(
            f"diagnosis needs channels {list(REQUIRED)}; missing or empty: {missing}; have {sorted(signals)}")


def prepare(signals: SignalSet, events: Sequence[Event], params: WindowParams | None = None
            ) -> tuple[list[DiagEvent], NoiseFloor, list[dict[str, object]]]:
    """Diagnosis event data, the noise floor, and the events left out (with reasons).

    Parameters
    ----------
    signals : decoded signals with ``motor_torque_nm`` and ``motor_speed_rpm``.
    events : detected events (:func:`app.analysis.events.detect_events`); excluded ones are skipped.
    params : window settings.
    """
    p = params or WindowParams()
    require_channels(signals)
    tq, sp = signals[TORQUE], signals[SPEED]
    # frames a buffering logger held and wrote back-to-back get their sampling times back (before the
    # invalid values are dropped, so a run keeps its frame count)
    tq_time, tq_fix = retime_bursts(tq.t, sample_period(tq.t)) if tq.t.size > 1 else (tq.t, Retimed())
    sp_time, sp_fix = retime_bursts(sp.t, sample_period(sp.t)) if sp.t.size > 1 else (sp.t, Retimed())
    ok_t, ok_s = np.isfinite(tq.values), np.isfinite(sp.values)
    tq_t, tq_v = tq_time[ok_t], tq.values[ok_t]
    sp_t, sp_v = sp_time[ok_s], sp.values[ok_s]
    if sp_t.size < 5 or tq_t.size < 5:
        raise InsufficientDataError(f"{TORQUE} has {tq_t.size} and {SPEED} {sp_t.size} finite samples")
    quiet = np.ones(sp_t.size, dtype=bool)
    quiet_tq = np.ones(tq_t.size, dtype=bool)
    for ev in events:
        quiet &= ~((sp_t >= ev.t_start_s) & (sp_t <= ev.t_end_s))
        quiet_tq &= ~((tq_t >= ev.t_start_s) & (tq_t <= ev.t_end_s))
    fixed = tq_fix + sp_fix
    noise = replace(estimate_noise_floor(sp_t, sp_v, quiet), torque_step_nm=quantisation_step(tq_v),
                    torque_sigma_nm=white_noise_sigma(tq_t, tq_v, quiet_tq), retimed_bursts=fixed.bursts,
                    retimed_frames=fixed.frames, unresolved_bursts=fixed.unresolved)
    slope = measured_slope(sp_t, sp_v)
    out: list[DiagEvent] = []
    skipped: list[dict[str, object]] = []
    for ev in events:
        if not ev.included:
            skipped.append({"index": ev.index, "reason": ev.exclusion})
            continue
        t0 = max(ev.t_cross_s - p.pre_s, ev.t_start_s)
        t1 = min(ev.t_cross_s + p.post_s, ev.t_end_s)
        ms = (sp_t >= t0) & (sp_t <= t1)
        t_sim = warm_start(tq_t, tq_v, t0 - MARGIN_S, p)
        mt = (tq_t >= min(t_sim, t0) - p.torque_margin_s) & (tq_t <= t1 + p.torque_margin_s)
        pre = sp_t[ms] < ev.t_cross_s - p.anchor_end_s
        if not enough_samples(sp_t[ms], ev.t_cross_s, p) or int(pre.sum()) < 2 or int(mt.sum()) < 3:
            skipped.append({"index": ev.index, "reason": (
                f"too few samples in the diagnosis window {t0:.3f}-{t1:.3f} s: {int(ms.sum())} speed, "
                f"{int(pre.sum())} before the crossing, {int(mt.sum())} torque (needs {p.min_samples} speed, or "
                f"{p.min_samples_low_rate} reaching {p.min_post_cover_s:g} s past the crossing; 2 before it; 3 "
                "torque)")})
            continue
        out.append(DiagEvent(
            index=ev.index, kind=ev.kind.value, t_event=ev.t_cross_s, t_start=float(t0), t_end=float(t1),
            speed_rpm=float(ev.motor_speed_rpm), torque_step_nm=float(ev.torque_after_nm - ev.torque_before_nm),
            torque_t=tq_t[mt], torque_nm=tq_v[mt], speed_t=sp_t[ms], speed_meas=sp_v[ms],
            var=noise.variance(slope[ms]), pre=pre,
            sim_t0=t_sim if t_sim < t0 - MARGIN_S else None,
            speed_init_rpm=speed_at(sp_t, sp_v, t_sim) if t_sim < t0 - MARGIN_S else None,
        ))
    return out, noise, skipped
