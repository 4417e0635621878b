"""Wheel slip inside an event window: the motor turning faster (or slower) than the road allows.

The simulator's tyres grip; a driven wheel that spins up (or locks) makes the measured motor
speed leave the vehicle's, and the ripple of such an event says nothing about the driveline.
The reference is the road speed seen at the motor: each wheel-speed channel
(``wheel_speed_*_rpm``) times the overall ratio, and ``vehicle_speed_kmh`` through the tyre
radius; at every motor-speed sample the **slowest** reference counts (under drive a spinning
wheel is faster than the road, the undriven wheels are not). The slip

``s(t) = mean(n_motor) / mean(ratio * n_ref) - 1``, means over ``[t, t + SLIP_AVERAGE_S]``,

is checked where the reference is at least ``min_speed_rpm`` at the motor; ``|s| > max_slip``
anywhere in the window excludes the event, with the worst value and its time.

A vehicle file whose ratio or tyre radius does not fit the log would make every event "slip".
So the log's own motor-to-road ratio (lower quartile over the log, :func:`log_ratio_scale`:
a spinning wheel only raises it, so a log that spins half the time still gives the true one) is
compared with the file's first; beyond ``max_slip`` the pipeline says so and checks slip
against the log's ratio instead. The average
spans a few shuffle periods: the shuffle itself swings the motor against the wheels by
hundreds of rpm for a moment (the half-shafts winding up), a spinning wheel stays away.

A road-speed channel a vehicle control unit computed from the motor speed follows every spin
of the motor (:func:`app.analysis.logchecks.computed_road_speed`); such channels are named in
``Drive.computed`` and never used as the reference.

Without a reference the spin is found from the motor alone (:func:`spin_problem`): with the
wheels gripping, the motor cannot gain speed faster than the driving torque accelerates the
whole vehicle, ``T / J`` with ``J`` the vehicle and driveline inertia referred to the motor.
Over ``[t, t + SLIP_AVERAGE_S]`` the least-squares slope of the motor speed (in the direction
it turns) is compared with ``spin_margin`` x the mean driving torque over ``J`` plus a road allowance
(``SPIN_ROAD_ACCEL_MS2``, a steep downhill); beyond it the event is excluded as wheel spin.
A braked or locking wheel is not judged this way (brakes decelerate beyond any regeneration
torque; the brake channels exclude those events).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from app.analysis.series import FloatArray, moving_mean
from app.signals import SignalSet
from sim.units import rad_s_to_rpm

WHEEL_PREFIX = "wheel_speed_"
VEHICLE_SPEED = "vehicle_speed_kmh"
SPEED = "motor_speed_rpm"
SLIP_AVERAGE_S = 0.5  # s; at least one and a half periods of a 3 Hz shuffle
TORQUE = "motor_torque_nm"
SPIN_ROAD_ACCEL_MS2 = 1.5  # m/s^2 the road may add to the torque's acceleration (a 15 % downhill)


@dataclass(frozen=True)
class Drive:
    """What relates motor speed to road speed: overall ratio (motor / wheel) and tyre radius (m)."""

    ratio: float
    wheel_radius_m: float | None = None
    inertia_kgm2: float | None = None  # vehicle and driveline referred to the motor: wheel spin without a reference
    spin_margin: float = 1.5  # the motor may gain speed this many times faster than torque / inertia
    computed: frozenset[str] = frozenset()  # road-speed channels computed from the motor speed: not references


def road_speed_at_motor(signals: SignalSet, t: FloatArray, drive: Drive) -> tuple[FloatArray, list[str]]:
    """Slowest reference speed at the motor (rpm) at times ``t`` (NaN where none), and the channels used."""
    refs: list[FloatArray] = []
    used: list[str] = []
    for name in sorted(signals):
        if name in drive.computed:
            continue
        if name.startswith(WHEEL_PREFIX) and name.endswith("_rpm") and len(signals[name]):
            refs.append(np.abs(signals[name].at(t)) * drive.ratio)
            used.append(name)
    if (VEHICLE_SPEED in signals and VEHICLE_SPEED not in drive.computed and len(signals[VEHICLE_SPEED])
            and drive.wheel_radius_m):
        v_ms = np.abs(signals[VEHICLE_SPEED].at(t)) / 3.6
        refs.append(rad_s_to_rpm(v_ms / drive.wheel_radius_m) * drive.ratio)
        used.append(VEHICLE_SPEED)
    if not refs:
        return np.full(t.size, np.nan), used
    stack = np.vstack(refs)
    ok = np.isfinite(stack)
    ref = np.where(ok.any(axis=0), np.min(np.where(ok, stack, np.inf), axis=0), np.nan)
    return ref, used


def slip_problem(signals: SignalSet, t0: float, t1: float, drive: Drive | None, max_slip: float,
                 min_speed_rpm: float) -> str | None:
    """Why the window ``[t0, t1]`` (s) is spoiled by wheel slip, or None (also without a reference)."""
    if drive is None or SPEED not in signals or not drive.ratio > 0:
        return None
    w = signals[SPEED].window(t0, t1)
    if not w.t.size:
        return None
    ref, used = road_speed_at_motor(signals, w.t, drive)
    if not used:
        return spin_problem(signals, t0, t1, drive)
    ok = np.isfinite(ref) & np.isfinite(w.values) & (ref >= min_speed_rpm)
    if not ok.any():
        return None
    tt = w.t[ok]
    motor = moving_mean(tt, np.abs(w.values[ok]), SLIP_AVERAGE_S)
    road = moving_mean(tt, ref[ok], SLIP_AVERAGE_S)
    s = motor / road - 1.0
    k = int(np.argmax(np.abs(s)))
    if abs(s[k]) <= max_slip:
        return None
    tk = float(tt[k])
    return (f"wheel slip: motor speed {float(motor[k]):.0f} rpm vs {float(road[k]):.0f} rpm from "
            f"{' / '.join(used)} x ratio {drive.ratio:g} ({100 * s[k]:+.0f} %, limit ±{100 * max_slip:g} %) "
            f"over {tk:.2f}-{tk + SLIP_AVERAGE_S:.2f} s")


def _window_slopes(t: FloatArray, y: FloatArray, window_s: float) -> FloatArray:
    """Least-squares slope of ``y`` over ``[t_i, t_i + window_s]`` for every sample ``i`` (a straight line
    through a few shuffle periods: the swings at the window's ends do not decide it)."""
    x = t - t[0]
    c = [np.concatenate(([0.0], np.cumsum(a))) for a in (np.ones_like(x), x, y, x * x, x * y)]
    i = np.arange(t.size)
    hi = np.searchsorted(t, t + window_s, side="right")
    n, sx, sy, sxx, sxy = (a[hi] - a[i] for a in c)
    den = n * sxx - sx * sx
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.asarray(np.where(den > 0, (n * sxy - sx * sy) / den, 0.0), dtype=np.float64)


def spin_problem(signals: SignalSet, t0: float, t1: float, drive: Drive) -> str | None:
    """Why ``[t0, t1]`` (s) is spoiled by wheel spin seen from the motor alone, or None (see the module docstring).

    None without ``drive.inertia_kgm2`` or a torque channel.
    """
    if not drive.inertia_kgm2 or TORQUE not in signals or not drive.ratio > 0:
        return None
    w = signals[SPEED].window(t0, t1)
    ok = np.isfinite(w.values)
    tt, v = w.t[ok], w.values[ok]
    if tt.size < 3:
        return None
    tq = signals[TORQUE].at(tt)
    if not np.isfinite(tq).all():
        return None
    i = np.flatnonzero(tt[-1] - tt >= SLIP_AVERAGE_S)
    if not i.size:
        return None
    way = np.sign(v[i])  # the gain of speed in the direction the motor turns
    gain = way * _window_slopes(tt, v, SLIP_AVERAGE_S)[i]  # rpm/s
    drive_tq = np.maximum(way * moving_mean(tt, tq, SLIP_AVERAGE_S)[i], 0.0)
    road = SPIN_ROAD_ACCEL_MS2 / drive.wheel_radius_m * drive.ratio if drive.wheel_radius_m else 0.0  # rad/s^2
    allowed = rad_s_to_rpm(drive.spin_margin * drive_tq / drive.inertia_kgm2 + road)
    k = int(np.argmax(gain - allowed))
    if gain[k] <= allowed[k]:
        return None
    tk = float(tt[i[k]])
    return (f"wheel spin: the motor gains {gain[k]:.0f} rpm/s over {tk:.2f}-{tk + SLIP_AVERAGE_S:.2f} s; "
            f"{drive_tq[k]:.0f} N m on {drive.inertia_kgm2:.3g} kg m^2 (the vehicle at the motor) allows at most "
            f"{allowed[k]:.0f} rpm/s (x{drive.spin_margin:g}, with a {SPIN_ROAD_ACCEL_MS2:g} m/s^2 road allowance); "
            "no wheel speed to compare with")


def log_ratio_scale(signals: SignalSet, drive: Drive, min_speed_rpm: float) -> float | None:
    """Lower quartile over the log of motor speed / road speed at the motor (1.0: the file's ratio fits).

    None without a reference channel or with fewer than 20 samples above ``min_speed_rpm``.
    """
    if SPEED not in signals or not len(signals[SPEED]):
        return None
    sp = signals[SPEED]
    ref, _ = road_speed_at_motor(signals, sp.t, drive)
    ok = np.isfinite(ref) & np.isfinite(sp.values) & (ref >= min_speed_rpm)
    if ok.sum() < 20:
        return None
    return float(np.percentile(np.abs(sp.values[ok]) / ref[ok], 25.0))
