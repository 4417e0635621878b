"""Tip-in and tip-out events from motor-torque zero crossings, corroborated by the pedal.

A torque reversal is tracked with a hysteresis band ``±hysteresis_nm``: the torque must
leave the band on one side and reach it on the other. The crossing time is where the
torque passes zero between those two band exits (linear interpolation)::

    torque
      ^            ______  +h .............  the torque reaches +h: reversal confirmed
      |           /
    0 +----------x------------------------   t_cross = interpolated zero crossing
      |  ______ /
      |            -h ....................   the torque left -h: candidate starts
      +-------------------------------------> t
         |<- pre_s ->|<----- post_s ----->|  event window [t_start, t_end]

A candidate becomes an event when the torque step (median before vs after) is at least
``min_step_nm`` and the torque rate at the crossing is at least ``min_rate_nm_s``.
Events are then *excluded* (kept in the list with a reason) for missing data, braking,
low speed, a pedal that does not corroborate the reversal, or a window cut short by the
next reversal.
"""

from __future__ import annotations

import enum
from dataclasses import asdict, dataclass

import numpy as np

from app.analysis.series import FloatArray, finite_signal, median_in
from app.errors import InsufficientDataError, MissingSignalError
from app.signals import Signal, SignalSet

TORQUE = "motor_torque_nm"
SPEED = "motor_speed_rpm"
PEDAL = "pedal_pct"
VEHICLE_SPEED = "vehicle_speed_kmh"


class EventKind(enum.StrEnum):
    TIP_IN = "tip_in"  # torque from negative (regen/coast) to positive (drive)
    TIP_OUT = "tip_out"  # torque from positive to negative


@dataclass(frozen=True)
class EventParams:
    """Detection and exclusion thresholds (units in the names)."""

    hysteresis_nm: float = 5.0
    min_step_nm: float = 30.0
    min_rate_nm_s: float = 100.0
    rate_half_window_s: float = 0.02  # torque slope fitted over t_cross ± this (at least 2 samples)
    step_before_s: tuple[float, float] = (0.30, 0.05)  # torque_before: median over t_cross - [a, b]
    step_after_s: tuple[float, float] = (0.15, 0.45)  # torque_after: median over t_cross + [a, b]
    pre_s: float = 0.5
    post_s: float = 1.5
    min_post_s: float = 0.6  # shorter post-windows (next reversal too soon) are excluded
    pedal_lead_s: float = 0.5  # pedal_before is read this long before the crossing
    pedal_lag_s: float = 0.3  # pedal_after is read this long after the crossing
    min_pedal_step_pct: float = 2.0
    min_vehicle_speed_kmh: float = 3.0
    min_motor_speed_rpm: float = 100.0  # used when the log has no vehicle speed
    brake_threshold: float = 0.5  # any brake_* channel above this inside the window = braking
    max_sample_gap_s: float = 0.1  # larger gaps in torque/speed inside a window = missing data

    def __post_init__(self) -> None:
        for name in ("hysteresis_nm", "min_step_nm", "pre_s", "post_s", "max_sample_gap_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"EventParams.{name} = {getattr(self, name)!r}: must be > 0")
        if self.min_post_s > self.post_s:
            raise ValueError(f"EventParams.min_post_s = {self.min_post_s!r}: must not exceed post_s = {self.post_s}")


@dataclass(frozen=True)
class Event:
    """One torque reversal. Times in s since the start of the measurement."""

    index: int
    kind: EventKind
    t_cross_s: float
    t_start_s: float
    t_end_s: float
    torque_before_nm: float
    torque_after_nm: float
    torque_rate_nm_s: float  # slope at the zero crossing (signed)
    vehicle_speed_kmh: float | None  # at the crossing; None without a vehicle speed channel
    motor_speed_rpm: float
    pedal_before_pct: float | None = None
    pedal_after_pct: float | None = None
    pedal_corroborated: bool | None = None  # None: the log has no pedal channel
    exclusion: str | None = None  # why the event is not analysed; None = included

    @property
    def included(self) -> bool:
        return self.exclusion is None

    @property
    def direction(self) -> float:
        """+1 for tip-in, -1 for tip-out: the sign the gap-open speed excursion takes."""
        return 1.0 if self.kind is EventKind.TIP_IN else -1.0

    def to_dict(self) -> dict[str, object]:
        d = asdict(self)
        d["kind"] = self.kind.value
        d["included"] = self.included
        return d


@dataclass(frozen=True)
class _Candidate:
    kind: EventKind
    t_cross: float
    i_left: int  # last sample outside the band on the old side
    i_right: int  # first sample outside the band on the new side


def _candidates(t: FloatArray, tq: FloatArray, h: float) -> list[_Candidate]:
    state = np.where(tq > h, 1, np.where(tq < -h, -1, 0))
    idx = np.flatnonzero(state)
    if idx.size < 2:
        return []
    s = state[idx]
    flips = np.flatnonzero(s[1:] != s[:-1])
    out: list[_Candidate] = []
    for f in flips:
        i_left, i_right = int(idx[f]), int(idx[f + 1])
        seg = tq[i_left:i_right + 1]
        # last sign change between the band exits: the crossing that ends the reversal
        sign_change = np.flatnonzero(np.signbit(seg[:-1]) != np.signbit(seg[1:]))
        k = i_left + int(sign_change[-1]) if sign_change.size else i_left
        t0, t1, y0, y1 = t[k], t[k + 1], tq[k], tq[k + 1]
        tc = float(t0 + (t1 - t0) * (-y0) / (y1 - y0)) if y1 != y0 else float(t0)
        kind = EventKind.TIP_IN if s[f + 1] > 0 else EventKind.TIP_OUT
        out.append(_Candidate(kind, tc, i_left, i_right))
    return out


def _rate(t: FloatArray, tq: FloatArray, c: _Candidate, half: float) -> float:
    lo = int(np.searchsorted(t, c.t_cross - half))
    hi = int(np.searchsorted(t, c.t_cross + half, side="right"))
    lo, hi = min(lo, c.i_left), max(hi, c.i_right + 1)
    if hi - lo < 2:
        return float("nan")
    slope = np.polyfit(t[lo:hi] - c.t_cross, tq[lo:hi], 1)[0]
    return float(slope)


def _gap_problem(sig: Signal, t0: float, t1: float, max_gap: float) -> str | None:
    if not len(sig) or sig.t[0] > t0 or sig.t[-1] < t1:
        return f"missing data: {sig.name} does not cover the window {t0:.3f}-{t1:.3f} s"
    w = sig.window(t0, t1)
    if w.t.size < 3:
        return f"missing data: {sig.name} has {w.t.size} samples in the window"
    edges = np.concatenate(([t0], w.t, [t1]))
    gaps = np.diff(edges)
    worst = int(np.argmax(gaps))
    if gaps[worst] > max_gap:
        return f"missing data: {sig.name} has a {gaps[worst]:.3f} s gap at t={edges[worst]:.3f} s"
    if not np.all(np.isfinite(w.values)):
        bad = w.t[~np.isfinite(w.values)][0]
        return f"missing data: {sig.name} is not available at t={bad:.3f} s"
    return None


def _brake_problem(signals: SignalSet, t0: float, t1: float, threshold: float) -> str | None:
    for name in sorted(signals):
        if not name.startswith("brake"):
            continue
        w = signals[name].window(t0, t1)
        vals = np.concatenate([w.values, signals[name].at([t0])])
        vals = vals[np.isfinite(vals)]
        if vals.size and float(vals.max()) > threshold:
            return f"braking: {name} = {float(vals.max()):g} > {threshold:g} inside the window"
    return None


def detect_events(signals: SignalSet, params: EventParams | None = None) -> list[Event]:
    """Find tip-in/tip-out events; excluded ones are returned too, with the reason.

    Parameters
    ----------
    signals
        Must hold ``motor_torque_nm`` and ``motor_speed_rpm``; ``pedal_pct``,
        ``vehicle_speed_kmh`` and ``brake*`` channels are used when present.
    params
        Thresholds; defaults suit 10-100 ms CAN periods and passenger-car torques.

    Returns
    -------
    list of Event, in time order, ``index`` counting from 0.
    """
    p = params or EventParams()
    for name in (TORQUE, SPEED):
        if name not in signals:
            raise MissingSignalError(f"event detection needs channel {name!r}; have {sorted(signals)}")
    torque = finite_signal(signals[TORQUE])
    if len(torque) < 3:
        raise InsufficientDataError(f"{TORQUE} has {len(torque)} finite samples; need at least 3")
    t, tq = torque.t, torque.values
    speed = signals[SPEED]
    pedal = signals.get(PEDAL)
    vspeed = signals.get(VEHICLE_SPEED)

    accepted: list[tuple[_Candidate, float, float, float]] = []
    for c in _candidates(t, tq, p.hysteresis_nm):
        before = median_in(torque, c.t_cross - p.step_before_s[0], c.t_cross - p.step_before_s[1])
        after = median_in(torque, c.t_cross + p.step_after_s[0], c.t_cross + p.step_after_s[1])
        before = float(tq[c.i_left]) if not np.isfinite(before) else before
        after = float(tq[c.i_right]) if not np.isfinite(after) else after
        rate = _rate(t, tq, c, p.rate_half_window_s)
        if abs(after - before) < p.min_step_nm or not abs(rate) >= p.min_rate_nm_s:
            continue
        accepted.append((c, before, after, rate))

    events: list[Event] = []
    for n, (c, before, after, rate) in enumerate(accepted):
        t_start = c.t_cross - p.pre_s
        t_end = c.t_cross + p.post_s
        exclusion: str | None = None
        if n + 1 < len(accepted):
            nxt = accepted[n + 1][0].t_cross
            t_end = min(t_end, nxt - min(p.pre_s, 0.5 * (nxt - c.t_cross)))
            if t_end - c.t_cross < p.min_post_s:
                exclusion = (f"window cut short: next torque reversal {nxt - c.t_cross:.3f} s after this one "
                             f"leaves {t_end - c.t_cross:.3f} s < min_post_s {p.min_post_s} s")
        for sig in (signals[TORQUE], speed):
            exclusion = exclusion or _gap_problem(sig, t_start, t_end, p.max_sample_gap_s)
        pb = pa = None
        corroborated: bool | None = None
        if pedal is not None and len(pedal):
            pb = float(pedal.at([c.t_cross - p.pedal_lead_s])[0])
            pa = float(pedal.at([c.t_cross + p.pedal_lag_s])[0])
            step = (pa - pb) if c.kind is EventKind.TIP_IN else (pb - pa)
            corroborated = bool(np.isfinite(step) and step >= p.min_pedal_step_pct)
            if not corroborated:
                exclusion = exclusion or (
                    f"pedal does not corroborate the {c.kind.value}: {pb:.1f} % -> {pa:.1f} % "
                    f"(need a {p.min_pedal_step_pct:g} % step)")
        exclusion = exclusion or _brake_problem(signals, t_start, t_end, p.brake_threshold)
        ms = float(speed.at([c.t_cross])[0])
        vs = float(vspeed.at([c.t_cross])[0]) if vspeed is not None and len(vspeed) else None
        if vs is not None and np.isfinite(vs):
            if abs(vs) < p.min_vehicle_speed_kmh:
                exclusion = exclusion or (
                    f"too low speed: vehicle speed {vs:.1f} km/h < {p.min_vehicle_speed_kmh:g} km/h")
        elif np.isfinite(ms) and abs(ms) < p.min_motor_speed_rpm:
            exclusion = exclusion or f"too low speed: motor speed {ms:.0f} rpm < {p.min_motor_speed_rpm:g} rpm"
        events.append(Event(
            index=n, kind=c.kind, t_cross_s=c.t_cross, t_start_s=t_start, t_end_s=t_end,
            torque_before_nm=before, torque_after_nm=after, torque_rate_nm_s=rate,
            vehicle_speed_kmh=vs if vs is not None and np.isfinite(vs) else None, motor_speed_rpm=ms,
            pedal_before_pct=pb, pedal_after_pct=pa, pedal_corroborated=corroborated, exclusion=exclusion,
        ))
    return events
