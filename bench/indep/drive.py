"""Torque drives as a driver and an anti-jerk controller make them.

A drive alternates driving and coasting/regenerating torque levels. Reversals come in clusters:
3-5 close ones (0.7-1.3 s apart) separated by longer holds (1.6-2.5 s), never further apart than
2.5 s. The torque follows the levels through a rate limiter whose rate drops near zero torque
(anti-jerk: the lash is crossed slowly), then a 20 ms moving average rounds the corners. Levels are
chosen so that a point-mass estimate of the vehicle speed stays inside the drive's speed band: the
driver asks for more when slow and coasts harder when fast.

Two bands per case: drive A (diagnosed) and drive B (withheld) differ in speed and pedal; each car
has its own (``BANDS``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.indep.car import Car, G, ratio
from bench.indep.dynamics import DT


@dataclass(frozen=True)
class Band:
    """Speed band (km/h) and torque bands (N m at the motor) of one drive."""

    speed_kmh: tuple[float, float]
    drive_nm: tuple[float, float]
    coast_nm: tuple[float, float]  # magnitudes of the negative levels


BAND_A = Band((18.0, 35.0), (35.0, 90.0), (15.0, 45.0))
BAND_B = Band((38.0, 60.0), (70.0, 140.0), (25.0, 70.0))
# The chain car (300 kg, ratio 3.8, 0.2 m wheels): 30 N m at the motor is 2 m/s^2, so the levels are a
# fraction of its ~230 N m peak, or a 0.7-2.5 s hold leaves the band (the planner then keeps the speed
# within ~15-45 km/h on drive A and ~20-65 km/h on drive B; peaks ~50 and ~75 N m).
CHAIN_A = Band((22.0, 36.0), (8.0, 35.0), (8.0, 30.0))
CHAIN_B = Band((34.0, 50.0), (12.0, 50.0), (10.0, 40.0))
# drives A and B per car
BANDS = {"paper": (BAND_A, BAND_B), "chain_drive": (CHAIN_A, CHAIN_B), "chain_low": (CHAIN_A, CHAIN_B)}


@dataclass(frozen=True)
class Drive:
    t: np.ndarray  # s, integration grid (step DT)
    torque: np.ndarray  # N m, CAN (reported) motor torque
    speed0_kmh: float
    reversals: np.ndarray  # s, times the torque crosses zero
    planned_end_kmh: float  # the planner's point-mass speed at the end


def _spacings(rng: np.random.Generator, duration: float) -> list[float]:
    out: list[float] = []
    while sum(out) < duration:
        out.extend(float(rng.uniform(0.7, 1.3)) for _ in range(int(rng.integers(3, 6))))
        out.append(float(rng.uniform(1.6, 2.5)))
    return out


def make_drive(car: Car, band: Band, rng: np.random.Generator, duration: float) -> Drive:
    """A drive of ``duration`` s in ``band`` (levels planned on a point-mass speed estimate)."""
    n = round(duration / DT) + 1
    t = np.arange(n) * DT
    ig, r = ratio(car), car.radius
    m_eff = car.mass + 2 * car.j_wheel / r**2 + car.j_rotor * ig**2 / r**2
    lo, hi = band.speed_kmh
    v = float(rng.uniform(lo + 0.25 * (hi - lo), hi - 0.25 * (hi - lo))) / 3.6
    v0 = v * 3.6
    rate_far = float(rng.uniform(500.0, 1500.0))  # N m/s
    rate_near = float(rng.uniform(120.0, 350.0))  # N m/s within the anti-jerk band around zero
    near = float(rng.uniform(6.0, 15.0))  # N m
    spacing = iter(_spacings(rng, duration + 5))
    level = (car.crr * car.mass * G + 0.5 * car.rho * car.cda * v * v) * r / ig  # cruise first
    next_switch = 1.5 + next(spacing)  # s: quasi-static first 1.5 s
    tq = np.empty(n)
    cur = level
    step = 10  # plan at 1 kHz, fill the 10 kHz grid by interpolation below
    coarse_t = t[::step]
    coarse = np.empty(coarse_t.size)
    h = DT * step
    for k, tk in enumerate(coarse_t):
        if tk >= next_switch:
            next_switch = tk + next(spacing)
            road = car.crr * car.mass * G + 0.5 * car.rho * car.cda * v * v
            hold_nm = road * r / ig
            pull = (0.5 * (lo + hi) / 3.6 - v) / (0.5 * (hi - lo) / 3.6)  # -1..1 inside the band
            if level <= 0:
                level = float(np.clip(rng.uniform(*band.drive_nm) * (1 + 1.5 * pull), band.drive_nm[0] * 0.4,
                                      band.drive_nm[1] * 1.3)) + hold_nm
            else:
                level = -float(np.clip(rng.uniform(*band.coast_nm) * (1 - 1.5 * pull), band.coast_nm[0] * 0.6,
                                       band.coast_nm[1] * 1.5))
        rate = rate_near if abs(cur) < near else rate_far
        cur += float(np.clip(level - cur, -rate * h, rate * h))
        coarse[k] = cur
        road = car.crr * car.mass * G + 0.5 * car.rho * car.cda * v * v
        v = max(v + h * (cur * ig / r - road) / m_eff, 1.0)
    win = round(0.02 / h)
    smooth = np.convolve(np.pad(coarse, (win // 2, win - 1 - win // 2), mode="edge"), np.ones(win) / win, mode="valid")
    tq = np.interp(t, coarse_t, smooth)
    s = np.sign(smooth)
    cross = coarse_t[1:][(s[1:] != s[:-1]) & (s[1:] != 0)]
    return Drive(t, tq, v0, cross, v * 3.6)
