"""Synthetic drive signals with known tip-in/tip-out timing, built by code with a fixed seed."""

from __future__ import annotations

import numpy as np

from app.signals import Interp, Signal, SignalSet

# (t_cross, torque_before, torque_after, ramp rate Nm/s)
REVERSALS = [(2.0, -50.0, 150.0, 1500.0), (5.0, 150.0, -60.0, -1200.0),
             (8.0, -60.0, 120.0, 900.0), (11.0, 120.0, -40.0, -800.0)]


def torque_profile(t: np.ndarray, reversals: list[tuple[float, float, float, float]]) -> np.ndarray:
    """Piecewise-constant torque with linear ramps crossing zero exactly at each t_cross."""
    out = np.full(t.shape, reversals[0][1])
    for tc, before, after, rate in reversals:
        t_a = tc - (0.0 - before) / rate  # ramp leaves `before` here ...
        t_b = tc + (after - 0.0) / rate  # ... and reaches `after` here
        ramp = before + rate * (t - t_a)
        out = np.where(t >= t_a, np.where(t <= t_b, ramp, after), out)
    return out


def drive(
    dt: float = 0.01, duration: float = 13.0, seed: int = 7, brake_at: float | None = None,
    speed_kmh: float = 25.0, pedal_follows: bool = True, speed_gap: tuple[float, float] | None = None,
) -> SignalSet:
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, dt)
    tq = torque_profile(t, REVERSALS) + rng.normal(0.0, 0.3, t.size)
    pedal = np.zeros_like(t)
    for tc, _b, after, _r in REVERSALS:
        # the pedal leads the torque by ~0.1 s; it is pressed for positive torque
        pedal = np.where(t >= tc - 0.1, 25.0 if after > 0 else 0.0, pedal)
    if not pedal_follows:
        pedal[:] = 10.0
    motor_rpm = speed_kmh * 1000 / 3600 / 0.33 * 11.0 * 60 / (2 * np.pi)
    speed = np.full_like(t, motor_rpm) + rng.normal(0.0, 0.5, t.size)
    ss = SignalSet()
    ss.add(Signal.from_samples("motor_torque_nm", t, tq, "Nm"))
    ts = t if speed_gap is None else t[(t < speed_gap[0]) | (t > speed_gap[1])]
    ss.add(Signal.from_samples("motor_speed_rpm", ts, speed[np.isin(t, ts)], "rpm"))
    ss.add(Signal.from_samples("pedal_pct", t, pedal, "%"))
    ss.add(Signal.from_samples("vehicle_speed_kmh", t, np.full_like(t, speed_kmh), "km/h"))
    brake = np.zeros_like(t) if brake_at is None else (np.abs(t - brake_at) < 0.2).astype(float)
    ss.add(Signal.from_samples("brake_pressed", t, brake, "", Interp.PREVIOUS))
    return ss


def damped_response(
    t: np.ndarray, freq_hz: float, zeta: float, amplitude: float, t0: float = 0.0
) -> np.ndarray:
    """``amplitude * exp(-sigma (t - t0)) * sin(omega_d (t - t0))`` for t >= t0, else 0."""
    wd = 2 * np.pi * freq_hz
    sigma = zeta * wd / np.sqrt(1 - zeta * zeta)
    tau = t - t0
    return np.where(tau >= 0, amplitude * np.exp(-sigma * np.maximum(tau, 0)) * np.sin(wd * tau), 0.0)
