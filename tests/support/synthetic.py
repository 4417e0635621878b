"""Truth drives for validating the diagnosis: a simulated drive measured the way a CAN log measures it.

A drive is a sequence of tip-ins and tip-outs (torque ramps through zero at random rates between
random drive and regen levels) whose durations keep the vehicle speed near a target. The truth is
the simulator run on the fine torque trace with the *truth* vehicle (the diagnosed vehicle plus
the withheld effect); the "measurement" samples it like an inverter on CAN:

- frames every ``period_s`` with a random phase, Gaussian timestamp jitter, random drop-outs;
- torque and speed values quantised to the DBC resolution, speed with Gaussian sensor noise (torque
  optionally too, ``CanSampling.torque_noise_nm``);
- a constant time offset between the torque and speed timestamps (the nuisance the diagnosis
  must fit, not attribute).

Torque and speed come in separate frames (each with its own phase, jitter and drop-outs) or, with
``shared_frame`` (1 kHz messages that carry both), in one frame whose torque value is the one valid
``offset_s`` earlier. :func:`measure_frames` also returns each frame's position in the sender's
sequence, so a log writer can fill alive counters that show the drop-outs
(:mod:`.truthlog` writes real BLF logs through a DBC).
"""

from __future__ import annotations

from collections.abc import Callable
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
    torque_noise_nm: float = 0.0  # white noise on the logged torque (an inverter's estimate), before quantisation
    jitter_s: float = 0.0002
    drop_fraction: float = 0.01
    offset_s: float = 0.0  # torque timestamps minus the time the value was valid
    shared_frame: bool = False  # torque and speed in one frame (same timestamps)


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


@dataclass(frozen=True)
class Frames:
    """CAN-like samples of one channel.

    Attributes
    ----------
    t : (k,) logged timestamps (s), increasing.
    values : (k,) physical values (before any DBC quantisation unless the sampling quantises).
    seq : (k,) position of each frame in the sender's sequence (drop-outs leave gaps).
    """

    t: FloatArray
    values: FloatArray
    seq: npt.NDArray[np.int64]


def _frame_times(duration: float, s: CanSampling, rng: np.random.Generator
                 ) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64]]:
    """Valid-at times, logged timestamps and sequence numbers of a periodic frame (jittered, with drop-outs)."""
    seq = np.arange(int(duration / s.period_s) - 1, dtype=np.int64)
    t_valid = float(rng.uniform(0, s.period_s)) + s.period_s * seq
    t_log = t_valid + np.abs(rng.normal(0.0, s.jitter_s, t_valid.size))
    keep = rng.random(t_valid.size) >= s.drop_fraction
    t_valid, t_log, seq = t_valid[keep], t_log[keep], seq[keep]
    order = np.argsort(t_log, kind="stable")
    return (np.asarray(t_valid[order], dtype=np.float64), np.asarray(t_log[order], dtype=np.float64),
            np.asarray(seq[order], dtype=np.int64))


def measure_frames(drive: Drive, truth: SimResult, s: CanSampling, rng: np.random.Generator) -> dict[str, Frames]:
    """CAN-like frames ``{channel: Frames}`` of torque and speed (see the module docstring)."""
    dur = float(drive.t[-1])
    tv, tl, seq = _frame_times(dur, s, rng)
    if s.shared_frame:
        tv2, tl2, seq2 = tv, tl, seq
        q = np.interp(tv - s.offset_s, drive.t, drive.torque_nm)
        tq_log = tl
    else:
        q = np.interp(tv, drive.t, drive.torque_nm)
        tq_log = tl + s.offset_s
        tv2, tl2, seq2 = _frame_times(dur, s, rng)
    if s.torque_noise_nm > 0:
        q = q + rng.normal(0.0, s.torque_noise_nm, q.size)
    if s.torque_res_nm > 0:
        q = np.round(q / s.torque_res_nm) * s.torque_res_nm
    sp = np.interp(tv2, truth.t, truth.motor_speed_rpm) + rng.normal(0.0, s.speed_noise_rpm, tv2.size)
    if s.speed_res_rpm > 0:
        sp = np.round(sp / s.speed_res_rpm) * s.speed_res_rpm
    return {"motor_torque_nm": Frames(tq_log, np.asarray(q, dtype=np.float64), seq),
            "motor_speed_rpm": Frames(tl2, np.asarray(sp, dtype=np.float64), seq2)}


def measure(drive: Drive, truth: SimResult, s: CanSampling, rng: np.random.Generator) -> dict[str, tuple[FloatArray,
                                                                                                           FloatArray]]:
    """CAN-like samples ``{channel: (timestamps, values)}`` of torque and speed."""
    return {k: (f.t, f.values) for k, f in measure_frames(drive, truth, s, rng).items()}


def to_signals(samples: dict[str, tuple[FloatArray, FloatArray]]) -> SignalSet:
    units = {"motor_torque_nm": "N m", "motor_speed_rpm": "rpm"}
    out = SignalSet()
    for name, (t, v) in samples.items():
        keep = t >= 0
        out.add(Signal.from_samples(name, t[keep], v[keep], units.get(name, ""), Interp.LINEAR))
    return out


def signal_ratio(drive: Drive, truth: SimResult, nominal: SimResult, noise_rpm: float, period_s: float = 0.01,
                 pre_s: float = 0.3, post_s: float = 1.0, anchor_end_s: float = 0.08) -> float:
    """How visible an effect is: RMS of truth minus nominal speed near reversals, in noise sigmas.

    Evaluated on a ``period_s`` grid inside ``[t_cross - pre_s, t_cross + post_s]`` of every torque
    zero crossing, each window's difference taken relative to its mean before ``t_cross -
    anchor_end_s`` -- as the diagnosis anchors each event on its pre-event samples. (Relative to one
    mean over the whole drive, the slow drift of two whole-drive simulations apart -- a drag
    decelerating the truth -- would count as signal, which no event window can see.)
    """
    t = np.arange(0.0, float(drive.t[-1]), period_s)
    diff = np.interp(t, truth.t, truth.motor_speed_rpm) - np.interp(t, nominal.t, nominal.motor_speed_rpm)
    cross = drive.t[np.flatnonzero(np.diff(np.signbit(drive.torque_nm)))]
    parts = []
    for tc in cross:
        window = (t > tc - pre_s) & (t < tc + post_s)
        anchor = window & (t < tc - anchor_end_s)
        if anchor.any():
            parts.append(diff[window] - np.mean(diff[anchor]))
    d = np.concatenate(parts) if parts else diff - np.mean(diff)
    return float(np.sqrt(np.mean(d * d)) / noise_rpm)


def toward_off(values: dict[str, float], off: dict[str, float], alpha: float) -> dict[str, float]:
    """Effect values moved toward the effect's ``off`` values: ``off + alpha * (value - off)``."""
    return {k: off[k] + alpha * (v - off[k]) for k, v in values.items()}


def scale_to_signal(make_truth: Callable[[dict[str, float]], SimResult], nominal: SimResult, drive: Drive,
                    values: dict[str, float], off: dict[str, float], target: float, noise_rpm: float,
                    period_s: float = 0.01, steps: int = 10) -> tuple[dict[str, float], float]:
    """Effect values scaled toward ``off`` so that the :func:`signal_ratio` is about ``target``.

    Bisection on ``alpha`` in (0, 1] (the ratio grows with ``alpha`` for every library effect); when
    even the full draw is fainter than ``target`` it is returned as it is. Returns (values, ratio).
    """
    def ratio(a: float) -> float:
        return signal_ratio(drive, make_truth(toward_off(values, off, a)), nominal, noise_rpm, period_s)

    r_full = ratio(1.0)
    if r_full <= target:
        return dict(values), r_full
    lo, hi, r_hi = 0.0, 1.0, r_full
    for _ in range(steps):
        mid = 0.5 * (lo + hi)
        r = ratio(mid)
        if r > target:
            hi, r_hi = mid, r
        else:
            lo = mid
    return toward_off(values, off, hi), r_hi
