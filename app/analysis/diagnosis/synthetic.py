"""Truth drives for validating the diagnosis: a simulated drive measured the way a CAN log measures it.

A drive is a sequence of tip-ins and tip-outs (torque ramps through zero at random rates between
random drive and regen levels) whose durations keep the vehicle speed near a target. The truth is
the simulator run on the fine torque trace with the *truth* vehicle (the diagnosed vehicle plus
the withheld effect); the "measurement" samples it like an inverter on CAN:

- frames every ``period_s`` with a random phase, Gaussian timestamp jitter, random drop-outs;
- torque and speed values quantised to the DBC resolution, speed with Gaussian sensor noise;
- a constant time offset between the torque and speed timestamps (the nuisance the diagnosis
  must fit, not attribute).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.signals import Interp, Signal, SignalSet
from sim import SimResult, Vehicle, simulate

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class DriveSpec:
    """Shape of a synthetic drive (torques at the motor, N m; times s; speeds km/h)."""

    duration_s: float = 60.0
    drive_nm: tuple[float, float] = (50.0, 150.0)
    regen_nm: tuple[float, float] = (-90.0, -30.0)
    hold_s: tuple[float, float] = (3.0, 3.8)
    ramp_rate_nm_s: tuple[float, float] = (900.0, 2200.0)
    speed_kmh: tuple[float, float] = (25.0, 55.0)
    start_kmh: float = 35.0
    smooth_s: float = 0.03  # jerk limit of the torque request: ramps pass a moving average this long


@dataclass(frozen=True)
class CanSampling:
    """How the CAN log measures the truth."""

    period_s: float = 0.01
    speed_noise_rpm: float = 0.5
    speed_res_rpm: float = 1.0
    torque_res_nm: float = 0.5
    jitter_s: float = 0.0002
    drop_fraction: float = 0.01
    offset_s: float = 0.0  # torque timestamps minus the time the value was valid


@dataclass(frozen=True)
class Drive:
    t: FloatArray  # (n,) fine grid, s
    torque_nm: FloatArray  # (n,) torque request, N m
    speed0_rpm: float


def motor_rpm(vehicle: Vehicle, kmh: float) -> float:
    return kmh / 3.6 / vehicle.wheel.radius * vehicle.ratio * 30.0 / np.pi


def make_drive(vehicle: Vehicle, rng: np.random.Generator, spec: DriveSpec | None = None, dt: float = 0.001) -> Drive:
    """A fine torque trace of alternating tip-ins and tip-outs that keeps the speed in range."""
    s = spec or DriveSpec()
    j_eq = vehicle.body.mass * vehicle.wheel.radius**2 / vehicle.ratio**2  # rigid, motor-referred (kg m^2)
    load = 8.0  # N m at the motor, rough road load for planning the durations only
    w = motor_rpm(vehicle, s.start_kmh) * np.pi / 30.0
    knots_t = [0.0]
    knots_q = [float(rng.uniform(*s.regen_nm))]
    t = 1.0 + float(rng.uniform(0.0, 0.5))
    while t < s.duration_s:
        q_prev = knots_q[-1]
        to_drive = q_prev < 0
        target = motor_rpm(vehicle, float(rng.uniform(*s.speed_kmh))) * np.pi / 30.0
        q_new = float(rng.uniform(*(s.drive_nm if to_drive else s.regen_nm)))
        ramp = abs(q_new - q_prev) / float(rng.uniform(*s.ramp_rate_nm_s))
        hold = float(rng.uniform(*s.hold_s))
        # stretch the hold toward the target speed (clipped to the allowed range)
        need = j_eq * (target - w) / (q_new - load)
        if need > 0:
            hold = float(np.clip(need, s.hold_s[0], s.hold_s[1] * 1.2))
        knots_t += [t, t + ramp]
        knots_q += [q_prev, q_new]
        w += ((q_prev + q_new) / 2 - load) * ramp / j_eq + (q_new - load) * hold / j_eq
        t += ramp + hold
    knots_t.append(s.duration_s)
    knots_q.append(knots_q[-1])
    tf = np.arange(0.0, s.duration_s, dt)
    q: FloatArray = np.interp(tf, knots_t, knots_q)
    k = max(round(s.smooth_s / dt), 1)
    if k > 1:
        q = np.convolve(np.pad(q, (k, k), mode="edge"), np.ones(k) / k, mode="same")[k:-k]
    return Drive(tf, q, motor_rpm(vehicle, s.start_kmh))


def run_truth(vehicle: Vehicle, drive: Drive, model: str = "multibody") -> SimResult:
    """The truth: the simulator on the fine torque trace."""
    return simulate(vehicle, drive.t, drive.torque_nm, model=model, speed0_rpm=drive.speed0_rpm,
                    interp="linear", output_dt=0.001)


def _frame_times(duration: float, s: CanSampling, rng: np.random.Generator) -> tuple[FloatArray, FloatArray]:
    """Valid-at times and logged timestamps of a periodic frame (jittered, with drop-outs)."""
    t_valid = float(rng.uniform(0, s.period_s)) + s.period_s * np.arange(int(duration / s.period_s) - 1)
    t_log = t_valid + np.abs(rng.normal(0.0, s.jitter_s, t_valid.size))
    keep = rng.random(t_valid.size) >= s.drop_fraction
    t_valid, t_log = t_valid[keep], t_log[keep]
    order = np.argsort(t_log, kind="stable")
    return np.asarray(t_valid[order], dtype=np.float64), np.asarray(t_log[order], dtype=np.float64)


def measure(drive: Drive, truth: SimResult, s: CanSampling, rng: np.random.Generator) -> dict[str, tuple[FloatArray,
                                                                                                           FloatArray]]:
    """CAN-like samples ``{channel: (timestamps, values)}`` of torque and speed."""
    dur = float(drive.t[-1])
    tv, tl = _frame_times(dur, s, rng)
    q = np.interp(tv, drive.t, drive.torque_nm)
    if s.torque_res_nm > 0:
        q = np.round(q / s.torque_res_nm) * s.torque_res_nm
    tv2, tl2 = _frame_times(dur, s, rng)
    sp = np.interp(tv2, truth.t, truth.motor_speed_rpm) + rng.normal(0.0, s.speed_noise_rpm, tv2.size)
    if s.speed_res_rpm > 0:
        sp = np.round(sp / s.speed_res_rpm) * s.speed_res_rpm
    return {"motor_torque_nm": (tl + s.offset_s, q), "motor_speed_rpm": (tl2, sp)}


def to_signals(samples: dict[str, tuple[FloatArray, FloatArray]]) -> SignalSet:
    units = {"motor_torque_nm": "N m", "motor_speed_rpm": "rpm"}
    out = SignalSet()
    for name, (t, v) in samples.items():
        keep = t >= 0
        out.add(Signal.from_samples(name, t[keep], v[keep], units.get(name, ""), Interp.LINEAR))
    return out
