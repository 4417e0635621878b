"""Tip-in and tip-out events a driver makes, corroborated by the pedal.

The torque is *driving* above ``+hysteresis_nm`` and not driving otherwise (coasting in the
band, regenerating below it); a tip-in enters the driving state, a tip-out leaves it, each
only when both sides dwell and the torque moves one way through the crossing (inverter
ringing is rejected: :mod:`app.analysis.reversals`). The crossing time is where the torque
passes zero next to the band exit (linear interpolation)::

    torque
      ^            ______  +h .............  the torque reaches +h: reversal confirmed
      |           /
    0 +----------x------------------------   t_cross = interpolated zero crossing
      |  ______ /
      |            -h ....................   (regeneration; a coast at 0 N m counts as well)
      +-------------------------------------> t
         |<- pre_s ->|<----- post_s ----->|  event window [t_start, t_end]

A candidate becomes an event when the torque step (median before vs after) is at least
``min_step_nm`` and the torque rate at the crossing is at least ``min_rate_nm_s``.
Events are then *excluded* (kept in the list with a reason) for missing data, braking (a window
whose brakes act only ``min_post_s`` or more after the reversal ends where they start instead),
low speed, wheel slip, a pedal that does not corroborate the reversal, or a window cut
short by the next reversal.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from operator import attrgetter

import numpy as np

from app.analysis.reversals import Reversal, ReversalParams, find_reversals
from app.analysis.series import finite_signal, median_in
from app.analysis.slip import Drive, slip_problem
from app.errors import InsufficientDataError, MissingSignalError
from app.serial import PLAIN, Serial, computed, rule
from app.signals import Signal, SignalSet

TORQUE = "motor_torque_nm"
SPEED = "motor_speed_rpm"
PEDAL = "pedal_pct"
VEHICLE_SPEED = "vehicle_speed_kmh"


class EventKind(enum.StrEnum):
    TIP_IN = "tip_in"  # torque from regeneration or coast (|T| <= hysteresis) to drive
    TIP_OUT = "tip_out"  # torque from drive to coast or regeneration


@dataclass(frozen=True)
class EventParams:
    """Detection and exclusion thresholds (units in the names)."""

    hysteresis_nm: float = 5.0  # driving above +this; coasting within ±this; regenerating below -this
    min_step_nm: float = 30.0
    min_rate_nm_s: float = 100.0  # in the event's direction (a tip-in with a falling torque is ringing)
    min_dwell_s: float = 0.08  # each side of a reversal must hold this long (inverter ringing does not)
    max_ramp_reversal: float = 0.3  # share of torque travel against the event's direction allowed at the crossing
    max_wheel_slip: float = 0.15  # |motor / (ratio x road speed) - 1| above this in the window = wheel slip
    slip_min_speed_rpm: float = 300.0  # slip is checked where the road speed at the motor is at least this
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
    brake_threshold: float = 0.5  # a brake* channel this far above its resting level inside the window = braking
    max_sample_gap_s: float = 0.1  # larger gaps in torque/speed inside a window = missing data ...
    max_lost_periods: float = 2.5  # ... or, on a slow channel, larger than this many of its mean sample spacings

    def __post_init__(self) -> None:
        for name in ("hysteresis_nm", "min_step_nm", "pre_s", "post_s", "max_sample_gap_s", "max_wheel_slip",
                     "max_lost_periods"):
            if not getattr(self, name) > 0:
                raise ValueError(f"EventParams.{name} = {getattr(self, name)!r}: must be > 0")
        if self.min_post_s > self.post_s:
            raise ValueError(f"EventParams.min_post_s = {self.min_post_s!r}: must not exceed post_s = {self.post_s}")
        for name in ("min_rate_nm_s", "min_dwell_s", "min_pedal_step_pct", "slip_min_speed_rpm"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"EventParams.{name} = {getattr(self, name)!r}: must be >= 0")
        if not 0 <= self.max_ramp_reversal <= 1:
            raise ValueError(f"EventParams.max_ramp_reversal = {self.max_ramp_reversal!r}: must be in [0, 1]")


@dataclass(frozen=True)
class Event(Serial):
    """One torque reversal. Times in s since the start of the measurement."""

    index: int
    kind: EventKind = field(metadata=rule(convert=attrgetter("value")))
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
    from_coast: bool = False  # the not-driving side is a coast (|T| <= hysteresis), not regeneration
    exclusion: str | None = None  # why the event is not analysed; None = included

    serial_computed = computed(included=PLAIN)

    @property
    def included(self) -> bool:
        return self.exclusion is None

    @property
    def direction(self) -> float:
        """+1 for tip-in, -1 for tip-out: the sign the gap-open speed excursion takes."""
        return 1.0 if self.kind is EventKind.TIP_IN else -1.0


MAX_INVALID_SHARE = 0.05  # invalid samples in an event window beyond which the channel is not available there


def gap_limit(sig: Signal, p: EventParams) -> float:
    """The longest gap between a channel's samples in an event window that is not missing data: ``max_sample_gap_s``,
    or ``max_lost_periods`` of its mean spacing over the log where that is longer (a 20 Hz logger that drops one
    frame leaves a 0.1 s gap; a 10 Hz one has them everywhere)."""
    if len(sig) < 2:
        return p.max_sample_gap_s
    spacing = float(sig.t[-1] - sig.t[0]) / (len(sig) - 1)
    return max(p.max_sample_gap_s, p.max_lost_periods * spacing)


def _gap_problem(sig: Signal, t0: float, t1: float, max_gap: float) -> str | None:
    if not len(sig) or sig.t[0] > t0 or sig.t[-1] < t1:
        return f"missing data: {sig.name} does not cover the window {t0:.3f}-{t1:.3f} s"
    w = sig.window(t0, t1)
    ok = np.isfinite(w.values)
    if int(ok.sum()) < 3:
        return f"missing data: {sig.name} has {int(ok.sum())} valid samples in the window"
    # an invalid sample (SNA, a failed checksum) is a missing one: isolated ones are dropped like lost frames
    # (a 1 kHz channel with 0.1 % of them has one in most windows), a run of them is a gap
    if not ok.all() and float(np.mean(~ok)) > MAX_INVALID_SHARE:
        bad = w.t[~ok][0]
        return (f"missing data: {sig.name} is not available at t={bad:.3f} s ({100 * float(np.mean(~ok)):.0f} % of "
                "the window's samples invalid)")
    edges = np.concatenate(([t0], w.t[ok], [t1]))
    gaps = np.diff(edges)
    worst = int(np.argmax(gaps))
    if gaps[worst] > max_gap:
        return (f"missing data: {sig.name} has a {gaps[worst]:.3f} s gap at t={edges[worst]:.3f} s (over "
                f"{max_gap:.3f} s)")
    return None


BRAKE_REST_PERCENTILE = 5.0  # a brake pressure's or travel's resting level: this percentile over the log
BRAKE_RANGE_SHARE = 0.05  # ... and it counts as applied this share of its range (99th percentile) above it


def brake_levels(signal: Signal, threshold: float) -> tuple[float, float]:
    """A brake channel's resting level and the value above which it says the brakes act.

    A switch (``brake_pressed``, 0/1) is applied above ``threshold``. A pressure or pedal travel (``brake``, in
    the DBC's unit) rests where the sensor's offset puts it -- 10 psi on a formula-student car's line pressure,
    not 0 -- so it is applied when it stands more than ``threshold``, or :data:`BRAKE_RANGE_SHARE` of the
    channel's range over the log, above its resting level (:data:`BRAKE_REST_PERCENTILE`). A foot resting on the
    pedal at a few percent of the braking pressure does not count; a log braked throughout has its resting level
    at the pressure of a stop and still counts each firm application.
    """
    v = signal.values[np.isfinite(signal.values)]
    if signal.name != "brake" or v.size == 0:
        return 0.0, threshold
    rest, top = (float(x) for x in np.percentile(v, [BRAKE_REST_PERCENTILE, 99.0]))
    return rest, rest + max(threshold, BRAKE_RANGE_SHARE * (top - rest))


def _brake_onset(signals: SignalSet, levels: dict[str, tuple[float, float]], t0: float, t1: float
                 ) -> tuple[float, str] | None:
    """The first time in ``[t0, t1]`` a brake is applied and what says so (None: never); ``levels``: each brake
    channel's :func:`brake_levels`, taken once per log."""
    first: tuple[float, str] | None = None
    for name, (rest, level) in levels.items():
        w = signals[name].window(t0, t1)
        t = np.concatenate([[t0], w.t])
        vals = np.concatenate([signals[name].at([t0]), w.values])
        on = np.flatnonzero(np.isfinite(vals) & (vals > level))
        if on.size and (first is None or t[on[0]] < first[0]):
            peak = float(np.nanmax(vals))
            first = (float(t[on[0]]), f"{name} = {peak:.4g} > {level:.3g}" + (f" (resting level {rest:.3g})"
                                                                              if rest else ""))
    return first


@dataclass(frozen=True)
class Detection:
    """Events (excluded ones with their reason) and how many torque changes were rejected as ringing."""

    events: list[Event]
    ringing: int = 0  # state changes that did not dwell or did not move one way (inverter ringing)
    small: int = 0  # reversals below min_step_nm or min_rate_nm_s


def detect_events(signals: SignalSet, params: EventParams | None = None, drive: Drive | None = None) -> list[Event]:
    """Find tip-in/tip-out events; excluded ones are returned too, with the reason (see :func:`find_events`)."""
    return find_events(signals, params, drive).events


def find_events(signals: SignalSet, params: EventParams | None = None, drive: Drive | None = None) -> Detection:
    """Find tip-in/tip-out events; excluded ones are returned too, with the reason.

    Parameters
    ----------
    signals
        Must hold ``motor_torque_nm`` and ``motor_speed_rpm``; ``pedal_pct``,
        ``vehicle_speed_kmh``, ``wheel_speed_*_rpm`` and ``brake*`` channels are used when present.
    params
        Thresholds; defaults suit 10-100 ms CAN periods and passenger-car torques.
    drive
        Overall ratio and tyre radius, for the wheel-slip check (:mod:`app.analysis.slip`);
        None skips it.

    Returns
    -------
    Detection; its events in time order, ``index`` counting from 0.
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

    found, ringing = find_reversals(t, tq, ReversalParams(p.hysteresis_nm, p.min_dwell_s, p.max_ramp_reversal,
                                                          p.rate_half_window_s))
    accepted: list[tuple[Reversal, float, float]] = []
    for c in found:
        before = median_in(torque, c.t_cross - p.step_before_s[0], c.t_cross - p.step_before_s[1])
        after = median_in(torque, c.t_cross + p.step_after_s[0], c.t_cross + p.step_after_s[1])
        before = float(tq[max(c.index - 1, 0)]) if not np.isfinite(before) else before
        after = float(tq[c.index]) if not np.isfinite(after) else after
        if abs(after - before) < p.min_step_nm or not abs(c.rate_nm_s) >= p.min_rate_nm_s:
            continue
        accepted.append((c, before, after))

    brakes = {name: brake_levels(signals[name], p.brake_threshold) for name in sorted(signals)
              if name.startswith("brake")}
    gap_limits = [(sig, gap_limit(sig, p)) for sig in (signals[TORQUE], speed)]
    events: list[Event] = []
    for n, (c, before, after) in enumerate(accepted):
        kind = EventKind.TIP_IN if c.tip_in else EventKind.TIP_OUT
        t_start = c.t_cross - p.pre_s
        t_end = c.t_cross + p.post_s
        exclusion: str | None = None
        if n + 1 < len(accepted):
            nxt = accepted[n + 1][0].t_cross
            t_end = min(t_end, nxt - min(p.pre_s, 0.5 * (nxt - c.t_cross)))
            if t_end - c.t_cross < p.min_post_s:
                exclusion = (f"window cut short: next torque reversal {nxt - c.t_cross:.3f} s after this one "
                             f"leaves {t_end - c.t_cross:.3f} s < min_post_s {p.min_post_s} s")
        for sig, limit in gap_limits:
            exclusion = exclusion or _gap_problem(sig, t_start, t_end, limit)
        pb = pa = None
        corroborated: bool | None = None
        if pedal is not None and len(pedal):
            pb = float(pedal.at([c.t_cross - p.pedal_lead_s])[0])
            pa = float(pedal.at([c.t_cross + p.pedal_lag_s])[0])
            step = (pa - pb) if c.tip_in else (pb - pa)
            corroborated = bool(np.isfinite(step) and step >= p.min_pedal_step_pct)
            if not corroborated:
                exclusion = exclusion or (
                    f"pedal does not corroborate the {kind.value}: {pb:.1f} % -> {pa:.1f} % "
                    f"(need a {p.min_pedal_step_pct:g} % step)")
        onset = _brake_onset(signals, brakes, t_start, t_end)
        if onset is not None and onset[0] - c.t_cross >= p.min_post_s:
            t_end = onset[0]  # braked after the reversal's response: the window ends where the brakes act
        elif onset is not None:
            exclusion = exclusion or (f"braking: {onset[1]} {onset[0] - c.t_cross:+.3f} s from the reversal, "
                                      f"under min_post_s {p.min_post_s} s after it")
        ms = float(speed.at([c.t_cross])[0])
        vs = float(vspeed.at([c.t_cross])[0]) if vspeed is not None and len(vspeed) else None
        if vs is not None and np.isfinite(vs):
            if abs(vs) < p.min_vehicle_speed_kmh:
                exclusion = exclusion or (
                    f"too low speed: vehicle speed {vs:.1f} km/h < {p.min_vehicle_speed_kmh:g} km/h")
        elif np.isfinite(ms) and abs(ms) < p.min_motor_speed_rpm:
            exclusion = exclusion or f"too low speed: motor speed {ms:.0f} rpm < {p.min_motor_speed_rpm:g} rpm"
        exclusion = exclusion or slip_problem(signals, t_start, t_end, drive, p.max_wheel_slip, p.slip_min_speed_rpm)
        events.append(Event(
            index=n, kind=kind, t_cross_s=c.t_cross, t_start_s=t_start, t_end_s=t_end,
            torque_before_nm=before, torque_after_nm=after, torque_rate_nm_s=c.rate_nm_s,
            vehicle_speed_kmh=vs if vs is not None and np.isfinite(vs) else None, motor_speed_rpm=ms,
            pedal_before_pct=pb, pedal_after_pct=pa, pedal_corroborated=corroborated, from_coast=c.from_coast,
            exclusion=exclusion,
        ))
    return Detection(events, ringing, len(found) - len(accepted))
