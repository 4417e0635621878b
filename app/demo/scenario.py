"""A scripted tip-in/tip-out drive, simulated and seen through realistic sensors.

The "true" vehicle is the paper preset with a chosen deviation (by default 20 % less
half-shaft clearance than the nominal tolerance midpoint), so an analysis against the
nominal preset has a real sim-to-measured difference to report. The driver presses and
releases the pedal repeatedly at 15-35 km/h, as in the paper's Section 3 test; one
release happens with the brake applied (an event the analysis must exclude).

Sensor effects applied to the simulated truth: torque and motor speed reported every
10 ms (speed 8 ms late through inverter filtering/CAN scheduling), like every other message
of the reference DBC; white noise, timestamp jitter; quantisation is left to the DBC encoding.
The ESP's longitudinal accelerometer (100 Hz) sees the simulated body acceleration through a
causal 30 Hz anti-alias filter, with a bias and white noise (drawn from their own generator, so
the other channels do not change with it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import signal as sps

from app.analysis.series import FloatArray
from sim import Vehicle, simulate


@dataclass(frozen=True)
class Channel:
    t: FloatArray  # s, shape (n,)
    values: FloatArray  # shape (n,)
    period_s: float


@dataclass(frozen=True)
class Scenario:
    duration_s: float = 90.0
    seed: int = 20220621
    speed_lag_s: float = 0.008
    speed_noise_rpm: float = 1.5
    torque_noise_nm: float = 0.4
    jitter_s: float = 0.0003
    truth_changes: dict[str, float] = field(default_factory=lambda: {"gaps.halfshaft": 0.8})  # factors on nominal
    brake_cycle: int = 5  # this release cycle happens with the brake pressed (-1: never)
    dropped_frames: int = 3  # frames of each message lost on the bus (their alive counters show the gaps)
    accel_noise_ms2: float = 0.04  # ESP longitudinal accelerometer: white noise ...
    accel_offset_ms2: float = 0.12  # ... bias and mounting tilt (0.7 degrees nose-up) ...
    accel_bandwidth_hz: float = 30.0  # ... and its anti-alias filter (2nd-order Butterworth, causal)


def _smooth_step(t: FloatArray, t0: float, a: float, b: float, rate: float) -> FloatArray:
    """From a to b starting at t0 with a constant rate (N m/s)."""
    dur = abs(b - a) / rate
    x = np.clip((t - t0) / dur, 0.0, 1.0)
    return np.asarray(a + (b - a) * x, dtype=np.float64)


def torque_script(vehicle: Vehicle, sc: Scenario, dt: float = 0.001) -> tuple[FloatArray, FloatArray, FloatArray,
                                                                            FloatArray]:
    """Driver script: returns ``t, torque_nm, pedal_pct, brake`` on a uniform grid (s)."""
    rng = np.random.default_rng(sc.seed)
    t = np.arange(0.0, sc.duration_s, dt)
    torque = np.full(t.size, -40.0)
    pedal = np.zeros(t.size)
    brake = np.zeros(t.size)
    mass_eff = vehicle.body.mass + 2 * (vehicle.wheel.inertia / vehicle.wheel.radius**2)
    gain = vehicle.ratio / vehicle.wheel.radius / mass_eff  # m/s^2 per N m of motor torque
    v0 = vehicle.body.speed_kmh / 3.6
    t_now, cycle, regen = 1.0, 0, -40.0
    while t_now < sc.duration_s - 5.0:
        drive = float(rng.uniform(60.0, 150.0))
        press = float(rng.uniform(1.6, 2.2))
        i0 = int(t_now / dt)
        pedal[i0 - 50:] = drive / 2.0  # the pedal leads the torque by 50 ms; 200 N m = 100 %
        torque[i0:] = _smooth_step(t[i0:], t_now, regen, drive, float(rng.uniform(700.0, 2000.0)))
        t_rel = t_now + press
        j0 = int(t_rel / dt)
        # rigid-body speed at the release, with rolling resistance (aero drag is small at these speeds)
        v = v0 + gain * float(np.sum(torque[:j0])) * dt - 9.81 * vehicle.body.rolling_resistance * t_rel
        regen = float(rng.uniform(-70.0, -35.0))
        # regenerate long enough to come back to ~22 km/h
        hold = float(np.clip((v - 22.0 / 3.6) / (gain * -regen), 1.6, 4.5))
        pedal[j0 - 50:] = 0.0
        torque[j0:] = _smooth_step(t[j0:], t_rel, drive, regen, float(rng.uniform(600.0, 1800.0)))
        if cycle == sc.brake_cycle:
            brake[j0 - 200:j0 + int(hold / dt)] = 1.0
        t_now = t_rel + hold
        cycle += 1
    return t, torque, pedal, brake


def _report(rng: np.random.Generator, t: FloatArray, y: FloatArray, period: float, start: float, lag: float,
            noise: float, jitter: float, t_end: float) -> Channel:
    ts = np.arange(start, t_end - lag - period, period)
    ts = ts + rng.uniform(-jitter, jitter, ts.size)
    vals = np.interp(ts - lag, t, y) + (rng.normal(0.0, noise, ts.size) if noise > 0 else 0.0)
    return Channel(ts, np.asarray(vals, dtype=np.float64), period)


def measured_channels(nominal: Vehicle, sc: Scenario | None = None) -> dict[str, Channel]:
    """Canonical channels as the CAN bus of the scripted drive would carry them."""
    sc = sc or Scenario()
    truth = nominal.with_changes({k: nominal.get(k) * f for k, f in sc.truth_changes.items()})
    t, torque, pedal, brake = torque_script(nominal, sc)
    res = simulate(truth, t, torque, model="multibody", interp="linear", output_dt=0.001)
    rng = np.random.default_rng(sc.seed + 1)
    end = float(res.t[-1])
    wheel = res.wheel_speed_rpm
    return {
        "motor_torque_nm": _report(rng, t, torque, 0.01, 0.002, 0.0, sc.torque_noise_nm, sc.jitter_s, end),
        "motor_speed_rpm": _report(rng, res.t, res.motor_speed_rpm, 0.01, 0.004, sc.speed_lag_s,
                                   sc.speed_noise_rpm, sc.jitter_s, end),
        "pedal_pct": _report(rng, t, pedal, 0.01, 0.006, 0.0, 0.0, sc.jitter_s, end),
        "brake_pressed": _report(rng, t, brake, 0.01, 0.006, 0.0, 0.0, sc.jitter_s, end),
        "vehicle_speed_kmh": _report(rng, res.t, res.vehicle_speed_kmh, 0.01, 0.008, 0.0, 0.02, sc.jitter_s, end),
        "brake": _report(rng, t, 15.0 * brake, 0.01, 0.008, 0.0, 0.0, sc.jitter_s, end),  # bar
        **{f"wheel_speed_{w}_rpm": _report(rng, res.t, wheel, 0.01, 0.009, 0.0, 0.3, sc.jitter_s, end)
           for w in ("fl", "fr", "rl", "rr")},
        "accel_long_ms2": _accelerometer(res.t, res.vehicle_accel_ms2, sc, end),
    }


def _accelerometer(t: FloatArray, accel: FloatArray, sc: Scenario, end: float) -> Channel:
    """The ESP's 100 Hz longitudinal acceleration: anti-alias filter, bias, noise, jitter."""
    rng = np.random.default_rng(sc.seed + 2)
    sos = sps.butter(2, sc.accel_bandwidth_hz, fs=1.0 / float(t[1] - t[0]), output="sos")
    seen = sps.sosfilt(sos, accel, zi=sps.sosfilt_zi(sos) * float(accel[0]))[0] + sc.accel_offset_ms2
    return _report(rng, t, np.asarray(seen, dtype=np.float64), 0.01, 0.003, 0.0, sc.accel_noise_ms2,
                   sc.jitter_s, end)
