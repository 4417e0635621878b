"""Checks of a decoded log before any comparison: sign, physical plausibility, computed road speeds.

Real logs arrive decoded with a DBC of the wrong version, with a torque channel whose sign
convention is the opposite of the speed's, or with "wheel speeds" a vehicle control unit
computed from the motor speed. Each of these gives numbers that look like answers (or no
events at all) without a word; :func:`check_log` finds them and says so, one
:class:`Finding` with a stable ``code`` per problem:

``torque_sign_inverted``
    The rank correlation of the torque with the motor acceleration over the log (both
    smoothed over ``accel_window_s``, so the shuffle and the sensor noise average out) is
    below ``-min_sign_correlation``: positive torque slows the motor down. A road load,
    regeneration and grade only shift the torque against the acceleration, they do not turn the
    relation round; the friction brakes can (a creep torque while the car brakes to a stop), so
    samples near a ``brake*`` channel above ``brake_threshold`` are left out. With
    ``fix_torque_sign`` (the default) the analysis goes on with the torque negated and says so.
``implausible_signal``
    Torque beyond ``torque_margin`` x the motor's peak torque, motor speed beyond the
    vehicle's top motor speed, or mechanical power ``T omega`` beyond ``power_margin`` x the
    motor's ``max_power_kw`` (:class:`Limits`), naming the channel, its extreme value and the
    limit. When more than ``max_implausible_share`` of a channel's samples are beyond its limit
    the log is refused (:class:`~app.errors.ImplausibleSignalError`): it was almost certainly
    decoded with the wrong DBC version or scaling.
``wheel_speed_computed``
    A wheel or vehicle speed that equals the motor speed times a constant within its
    quantisation while the motor shuffles against the wheels (``computed_tolerance``
    relative): no wheel follows the motor's shuffle that closely, so the channel was
    computed, not measured, and is not used as road truth (:mod:`app.analysis.slip`).
``speed_retimed``
    The signal map has a ``time_base`` (a timer or counter in the speed's own message): the
    speed samples are put at the times it gives (:func:`app.analysis.sampling.timer_times`)
    before anything else, and the finding says how far the logged stamps were off.
``time_base_unmatched``
    Fewer than half of the speed samples have a time-base value from the same frame: the
    speed keeps its logged stamps.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.analysis.events import SPEED, TORQUE, EventParams, brake_levels
from app.analysis.sampling import timer_times
from app.analysis.series import FloatArray, finite_signal, moving_mean, quantisation_step
from app.analysis.slip import VEHICLE_SPEED, WHEEL_PREFIX
from app.errors import ImplausibleSignalError
from app.serial import Serial
from app.signals import Signal, SignalSet
from sim import Vehicle
from sim.units import RAD_S_PER_RPM

TORQUE_SIGN_INVERTED = "torque_sign_inverted"
IMPLAUSIBLE_SIGNAL = "implausible_signal"
WHEEL_SPEED_COMPUTED = "wheel_speed_computed"
SPEED_RETIMED = "speed_retimed"
TIME_BASE_UNMATCHED = "time_base_unmatched"
TIME_BASE = "time_base"

MIN_BASE_SPEED_RPM = 2500.0  # lowest corner speed of a traction motor: peak torque <= max power / this
MAX_ROAD_SPEED_KMH = 250.0  # top road speed: the motor speed the ratio and tyre give there is its limit
SHUFFLE_TREND_S = 0.5  # the motor's own shuffle: its speed less the mean over this window


@dataclass(frozen=True)
class CheckParams:
    fix_torque_sign: bool = True  # analyse an inverted torque channel with its sign corrected
    min_sign_correlation: float = 0.3  # |rank correlation| of torque with acceleration to decide the sign
    accel_window_s: float = 0.2  # torque and speed smoothed over this before the acceleration is taken
    brake_threshold: float = EventParams.brake_threshold  # a brake* channel above this: not a sign sample
    torque_margin: float = 1.5  # decoded torque allowed up to this x the motor's peak torque
    speed_margin: float = 1.0  # decoded motor speed allowed up to this x the top motor speed
    power_margin: float = 1.5  # decoded T x omega allowed up to this x max_power_kw
    max_implausible_share: float = 0.5  # a channel beyond its limit this often: the log is refused
    computed_tolerance: float = 0.001  # relative ratio spread of a computed road speed (beyond quantisation)
    min_shuffle_rpm: float = 5.0  # motor samples at least this far from their trend test a road speed

    def __post_init__(self) -> None:
        for name in ("min_sign_correlation", "max_implausible_share"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"CheckParams.{name} = {getattr(self, name)!r}: must be in (0, 1]")
        for name in ("accel_window_s", "torque_margin", "speed_margin", "power_margin", "computed_tolerance",
                     "min_shuffle_rpm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"CheckParams.{name} = {getattr(self, name)!r}: must be > 0")


@dataclass(frozen=True)
class Limits:
    """What the vehicle's motor can do: peak torque (N m), top speed (rpm), peak power (kW)."""

    peak_torque_nm: float
    max_speed_rpm: float
    max_power_kw: float

    @classmethod
    def for_vehicle(cls, vehicle: Vehicle) -> Limits:
        """From the vehicle file: the peak torque is ``max_power_kw`` at ``MIN_BASE_SPEED_RPM`` (no traction
        motor has its corner lower), the top speed is the motor's at ``MAX_ROAD_SPEED_KMH`` through the
        overall ratio and the tyre radius."""
        power_w = vehicle.motor.max_power_kw * 1e3
        top = MAX_ROAD_SPEED_KMH / 3.6 / vehicle.wheel.radius * vehicle.ratio / RAD_S_PER_RPM
        return cls(power_w / (MIN_BASE_SPEED_RPM * RAD_S_PER_RPM), float(top), vehicle.motor.max_power_kw)


@dataclass(frozen=True)
class Finding(Serial):
    """One problem of the log as decoded: a stable ``code``, the channel, and what was found in words."""

    code: str
    channel: str
    message: str


@dataclass(frozen=True)
class LogChecks:
    """The signals to analyse (torque sign corrected when asked), the findings, and the road-speed channels
    computed from the motor speed (not road truth)."""

    signals: SignalSet
    findings: list[Finding]
    computed: frozenset[str]
    sign_correlation: float  # rank correlation of the decoded torque with the motor acceleration (NaN: unknown)


def _rank(x: FloatArray) -> FloatArray:
    r = np.empty(x.size)
    r[np.argsort(x, kind="stable")] = np.arange(x.size)
    return r


def sign_correlation(torque: Signal, speed: Signal, window_s: float, brakes: Sequence[Signal] = (),
                     brake_threshold: float = EventParams.brake_threshold) -> float:
    """Rank correlation of the torque with the motor acceleration, both averaged over ``window_s``, without
    the samples whose window sees one of ``brakes`` applied (:func:`~app.analysis.events.brake_levels`); NaN
    when fewer than 20 samples are left or either is constant."""
    t = speed.t[(speed.t >= torque.t[0]) & (speed.t <= torque.t[-1])] if len(torque) else speed.t[:0]
    if t.size < 20:
        return float("nan")
    v = moving_mean(t, speed.at(t), window_s)
    accel = np.gradient(v, t)
    tq = moving_mean(t, torque.at(t), window_s)
    ok = np.isfinite(accel) & np.isfinite(tq)
    for brake in brakes:
        pressed = np.nan_to_num(brake.at(t), nan=0.0) > brake_levels(brake, brake_threshold)[1]
        ok &= moving_mean(t, pressed.astype(np.float64), window_s) == 0.0
    if ok.sum() < 20 or np.ptp(accel[ok]) == 0 or np.ptp(tq[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(_rank(tq[ok]), _rank(accel[ok]))[0, 1])


def _beyond(name: str, t: FloatArray, values: FloatArray, limit: float, unit: str,
            what: str) -> tuple[Finding | None, float]:
    """A finding for ``values`` beyond ``limit`` (None when none is) and the share of samples beyond it."""
    over = np.abs(values) > limit
    if not over.any():
        return None, 0.0
    k = int(np.argmax(np.abs(values)))
    share = float(over.mean())
    return Finding(IMPLAUSIBLE_SIGNAL, name,
                   f"{name} reads {values[k]:+.0f} {unit} at t={t[k]:.2f} s, beyond {what} {limit:.0f} {unit} "
                   f"({100 * share:.1f} % of its samples)"), share


def plausibility(torque: Signal, speed: Signal, limits: Limits, p: CheckParams) -> list[Finding]:
    """Torque, speed and power against the vehicle's limits (see the module docstring).

    Raises ImplausibleSignalError when more than ``max_implausible_share`` of a channel's samples are beyond
    its limit.
    """
    power_kw = torque.at(speed.t) * speed.values * RAD_S_PER_RPM / 1e3
    ok = np.isfinite(power_kw)
    checks = (
        (TORQUE, torque.t, torque.values, p.torque_margin * limits.peak_torque_nm, "N m",
         f"{p.torque_margin:g} x the motor's peak torque"),
        (SPEED, speed.t, speed.values, p.speed_margin * limits.max_speed_rpm, "rpm",
         f"the motor speed at {MAX_ROAD_SPEED_KMH:g} km/h"),
        ("motor power", speed.t[ok], power_kw[ok], p.power_margin * limits.max_power_kw, "kW",
         f"{p.power_margin:g} x max_power_kw"),
    )
    found: list[Finding] = []
    for name, t, values, limit, unit, what in checks:
        finding, share = _beyond(name, t, values, limit, unit, what)
        if finding is None:
            continue
        if share > p.max_implausible_share:
            raise ImplausibleSignalError(
                f"{finding.message}: the log was most likely decoded with the wrong DBC version or scaling "
                "(check the signal's factor and the map's unit and factor)")
        found.append(finding)
    return found


def computed_road_speed(name: str, road: Signal, speed: Signal, p: CheckParams) -> Finding | None:
    """A finding when ``road`` is the motor speed times a constant through the motor's shuffle, else None.

    Tested on the motor samples at least ``min_shuffle_rpm`` away from their ``SHUFFLE_TREND_S`` mean (a
    steady cruise cannot tell a computed channel from a measured one); needs 20 of them.
    """
    t = speed.t
    ref = road.at(t)
    ok = np.isfinite(ref) & (np.abs(ref) > 0) & np.isfinite(speed.values) & (np.abs(speed.values) > 100.0)
    if ok.sum() < 20:
        return None
    tt, motor, ref = t[ok], speed.values[ok], ref[ok]
    shuffle = np.abs(motor - moving_mean(tt, motor, SHUFFLE_TREND_S)) >= p.min_shuffle_rpm
    if shuffle.sum() < 20:
        return None
    k = float(np.median(motor[shuffle] / ref[shuffle]))
    allowed = (abs(k) * quantisation_step(road.values) + quantisation_step(speed.values)
               + p.computed_tolerance * np.abs(motor[shuffle]))
    dev = np.abs(motor[shuffle] - k * ref[shuffle])
    if float(np.mean(dev <= allowed)) < 0.95:
        return None
    spread = float(np.percentile(np.abs(motor[shuffle] / (k * ref[shuffle]) - 1.0), 95))
    return Finding(WHEEL_SPEED_COMPUTED, name,
                   f"{name} is the motor speed x {1 / k:.6g} within {100 * spread:.3f} % through the shuffle "
                   f"({int(shuffle.sum())} samples): computed from the motor speed, not measured; not used as road "
                   "speed")


def retimed_speed(speed: Signal, timer: Signal) -> tuple[Signal, Finding]:
    """The speed at the times its frames' ``timer`` gives, and what was done, in words.

    Samples are paired with the timer values of the same frames (equal stamps); without a pair for half
    of them the speed is returned as logged.
    """
    timer = finite_signal(timer)
    common, i_s, i_t = np.intersect1d(speed.t, timer.t, return_indices=True)
    if common.size < max(20, speed.t.size // 2):
        return speed, Finding(TIME_BASE_UNMATCHED, TIME_BASE,
                              f"{TIME_BASE} comes with {common.size} of {speed.t.size} {SPEED} samples (it must be "
                              "a signal of the speed's own message): the speed keeps its logged stamps")
    t = timer_times(common, timer.values[i_t])
    off = np.abs(t - common) * 1e3
    order = np.argsort(t, kind="stable")
    out = Signal.from_samples(speed.name, t[order], speed.values[i_s][order], speed.unit, speed.interp,
                              speed.labels)
    return out, Finding(SPEED_RETIMED, SPEED,
                        f"{SPEED} re-timed from {TIME_BASE}: the logged stamps were off by up to {off.max():.1f} ms "
                        f"(95th percentile {np.percentile(off, 95):.1f} ms, median {np.median(off):.1f} ms)")


def check_log(signals: SignalSet, limits: Limits, params: CheckParams | None = None) -> LogChecks:
    """All checks of the module docstring on ``signals`` (which hold the torque and the motor speed)."""
    p = params or CheckParams()
    findings: list[Finding] = []
    out = signals
    if TIME_BASE in signals:
        retimed, said = retimed_speed(finite_signal(signals[SPEED]), signals[TIME_BASE])
        findings.append(said)
        out = SignalSet({**signals.signals, SPEED: retimed})
    torque, speed = finite_signal(out[TORQUE]), finite_signal(out[SPEED])
    findings += plausibility(torque, speed, limits, p)
    brakes = [out[name] for name in sorted(out) if name.startswith("brake") and len(out[name])]
    corr = sign_correlation(torque, speed, p.accel_window_s, brakes, p.brake_threshold)
    if np.isfinite(corr) and corr <= -p.min_sign_correlation:
        how = ("analysed with the sign corrected" if p.fix_torque_sign
               else "analysed as decoded, so every tip-in reads as a tip-out")
        findings.append(Finding(TORQUE_SIGN_INVERTED, TORQUE,
                                f"{TORQUE} is inverted relative to the motor speed: its rank correlation with the "
                                f"motor acceleration is {corr:.2f}; {how} (set invert = true for the channel in "
                                "the signal map)"))
        if p.fix_torque_sign:
            raw = out[TORQUE]
            out = SignalSet({**out.signals, TORQUE: Signal(raw.name, raw.t, -raw.values, raw.unit, raw.interp,
                                                           raw.labels)})
    computed: set[str] = set()
    for name in sorted(signals):
        if (name.startswith(WHEEL_PREFIX) and name.endswith("_rpm")) or name == VEHICLE_SPEED:
            road = computed_road_speed(name, finite_signal(signals[name]), speed, p)
            if road is not None:
                findings.append(road)
                computed.add(name)
    return LogChecks(out, findings, frozenset(computed), corr)
