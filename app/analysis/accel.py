r"""The vehicle's longitudinal acceleration: from an accelerometer, or derived from a road speed.

**Accelerometer** (channel ``accel_long_ms2``; an ESP/ABS longitudinal sensor or an IMU; the signal
map converts m/s^2 or g). Before it is used it is checked against the road speed
(:func:`check_accelerometer`): over the whole log both the accelerometer and the derivative of
the road speed are averaged over ``CHECK_AVERAGE_S`` (the shuffle and noise average out) and the
accelerometer is regressed on the derivative, ``a_sensor = slope * dv/dt + offset``. A level
road gives ``slope = 1``; the offset is the sensor's bias plus grade and mounting tilt
(``g sin(angle)``) and is removed before the criteria are computed. Verdicts:

``ok``          ``|slope - 1| <= 0.3``
``sign``        ``|slope + 1| <= 0.3``: the sensor's positive axis points backwards (``invert = true``)
``unit_g``      ``slope`` within 30 % of ``1/9.81``: the channel carries g, declared as m/s^2
``unit_ms2``    ``slope`` within 30 % of ``9.81``: the channel carries m/s^2, declared as g
``inconsistent`` any other slope (a wrong factor, a lateral axis)
``unchecked``   no road speed, or the log does not accelerate enough to tell (``MIN_CHECK_STD``)

Anything but ``ok`` and ``unchecked`` is a finding (``accel_sign``, ``accel_unit``,
``accel_inconsistent``) and the accelerometer is not used: the measured criteria come from the
road speed instead, and say so. **Saturation**: runs of at least ``SATURATION_RUN`` samples at the
channel's extreme value (the sensor's range) are a finding (``accel_saturated``); the criteria of
an event window holding such a run are nulled with that reason.

**Derived from speed** (no accelerometer): the road speed (``vehicle_speed_kmh``, else the mean of
the wheel speeds through the tyre radius) is resampled to a uniform grid at its own period,
low-passed with a zero-phase 4th-order Butterworth (``cutoff_hz``, at most 0.4 fs) and
differentiated with the five-point central difference
``a_i = (-v_{i+2} + 8 v_{i+1} - 8 v_{i-1} + v_{i-2}) / (12 h)`` (zero phase, gain error below 1 %
up to fs/8). The **bandwidth** reported is the frequency where the product of both responses
falls to 1/sqrt 2, computed from their exact frequency responses. The criteria that need more
than that (clunk always; kick, shuffle and jerk when the shuffle is above bandwidth / 1.5, where
the gain has fallen by 4 %) are marked ``unresolved``. A differentiator amplifies the speed's
noise: its RMS on the acceleration (``noise_ms2``) is the speed's white-noise RMS (second
differences, :func:`app.analysis.series.noise_rms`) times the filters' noise gain
(:func:`derivative_noise_gain`). A peak read through that noise is biased up by about one noise
RMS at each extremum, so for a derived acceleration kick and shuffle peak-to-peak are read off
the damped sine fitted to the shuffle (:mod:`app.analysis.drivability`), whose amplitude averages
the noise out, and are marked ``unresolved`` when the fit's amplitude is uncertain by more than
5 %.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np

from app.analysis.logchecks import Finding
from app.analysis.sampling import sample_period
from app.analysis.series import FloatArray, finite_signal, noise_rms
from app.analysis.slip import VEHICLE_SPEED, WHEEL_PREFIX
from app.analysis.zerophase import butter_sos, zero_phase
from app.errors import InsufficientDataError
from app.serial import Serial, lists, rule
from app.signals import Signal, SignalSet
from sim.units import rpm_to_rad_s

ACCEL = "accel_long_ms2"
G = 9.80665
CHECK_AVERAGE_S = 1.0
MIN_CHECK_STD = 0.15  # m/s^2: the averaged road acceleration must vary this much for a slope
SATURATION_RUN = 3
ACCEL_SIGN, ACCEL_UNIT, ACCEL_INCONSISTENT, ACCEL_SATURATED = (
    "accel_sign", "accel_unit", "accel_inconsistent", "accel_saturated")


@dataclass(frozen=True)
class AccelCheck(Serial):
    verdict: str  # ok | sign | unit_g | unit_ms2 | inconsistent | unchecked
    slope: float = math.nan
    offset_ms2: float = math.nan
    # (t0, t1) s of runs at the sensor's range
    saturated: tuple[tuple[float, float], ...] = field(default=(), metadata=rule(key="saturated_s", convert=lists))


@dataclass(frozen=True)
class AccelSource:
    """Uniform acceleration samples of a log and where they come from."""

    t: FloatArray  # s, (n,)
    a: FloatArray  # m/s^2, (n,)
    kind: str  # "accelerometer" | "vehicle_speed" | "wheel_speed"
    bandwidth_hz: float  # inf for an accelerometer
    check: AccelCheck | None = None
    findings: list[Finding] = field(default_factory=list)
    note: str = ""
    noise_ms2: float = math.nan  # derived: RMS the speed's own noise leaves on the acceleration (NaN: not known)

    @property
    def period_s(self) -> float:
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1)) if self.t.size > 1 else math.nan

    def saturated_in(self, t0: float, t1: float) -> bool:
        return any(s0 <= t1 and s1 >= t0 for s0, s1 in (self.check.saturated if self.check else ()))

    def describe(self) -> dict[str, object]:
        return {"kind": self.kind, "bandwidth_hz": self.bandwidth_hz if math.isfinite(self.bandwidth_hz) else None,
                "sample_period_s": self.period_s, "check": self.check.to_dict() if self.check else None,
                "note": self.note, "noise_ms2": self.noise_ms2 if math.isfinite(self.noise_ms2) else None}


def uniform(sig: Signal, period: float | None = None) -> tuple[FloatArray, FloatArray]:
    """``sig`` linearly resampled to a uniform grid at its own period (or ``period``)."""
    s = finite_signal(sig)
    if len(s) < 2:
        raise InsufficientDataError(f"{sig.name} has fewer than two samples")
    dt = period or sample_period(s.t)
    t = np.arange(s.t[0], s.t[-1] + 0.5 * dt, dt)
    return t, np.interp(t, s.t, s.values)


def five_point(v: FloatArray, h: float) -> FloatArray:
    """Five-point central derivative of uniform samples (second order at the two ends)."""
    d = np.gradient(v, h)
    if v.size >= 5:
        d[2:-2] = (-v[4:] + 8 * v[3:-1] - 8 * v[1:-3] + v[:-4]) / (12 * h)
    return np.asarray(d, dtype=np.float64)


@functools.lru_cache(maxsize=32)
def derivative_bandwidth(fs: float, cutoff_hz: float, order: int = 4) -> float:
    """-3 dB frequency (Hz) of the zero-phase low pass times the five-point stencil's gain."""
    fc = min(cutoff_hz, 0.4 * fs)
    f = np.linspace(0.01, 0.5 * fs, 4000)
    lp = 1.0 / (1.0 + (f / fc) ** (2 * order))  # |H|^2 of the forward-backward Butterworth
    x = 2 * np.pi * f / fs
    stencil = (8 * np.sin(x) - np.sin(2 * x)) / (6 * x)
    below = np.nonzero(lp * stencil < 1 / math.sqrt(2))[0]
    return float(f[below[0]]) if below.size else 0.5 * fs


@functools.lru_cache(maxsize=32)
def derivative_noise_gain(fs: float, cutoff_hz: float, order: int = 4) -> float:
    """RMS acceleration (m/s^2) per m/s RMS of white speed noise through the low pass and the stencil."""
    fc = min(cutoff_hz, 0.4 * fs)
    f = np.linspace(1e-3, 0.5 * fs, 4000)
    x = 2 * np.pi * f / fs
    h2 = (1.0 / (1.0 + (f / fc) ** (2 * order))) ** 2 * ((8 * np.sin(x) - np.sin(2 * x)) / 6 * fs) ** 2
    return float(np.sqrt(np.mean(h2)))


def derive(t: FloatArray, v_ms: FloatArray, cutoff_hz: float, order: int = 4) -> tuple[FloatArray, float]:
    """Acceleration (m/s^2) of uniform speed samples ``v_ms`` (m/s) and the differentiator's bandwidth (Hz)."""
    h = float((t[-1] - t[0]) / (t.size - 1))
    fs = 1.0 / h
    fs = float(f"{fs:.6g}")
    smooth = zero_phase(butter_sos(order, min(cutoff_hz, 0.4 * fs), "low", fs), v_ms)
    return five_point(smooth, h), derivative_bandwidth(fs, cutoff_hz, order)


def road_speed(signals: SignalSet, wheel_radius_m: float | None,
               computed: frozenset[str] = frozenset()) -> tuple[Signal, str] | None:
    """Road speed (m/s) from ``vehicle_speed_kmh``, else the mean of the wheel speeds; None without either."""
    if VEHICLE_SPEED in signals and VEHICLE_SPEED not in computed and len(finite_signal(signals[VEHICLE_SPEED])) > 8:
        s = finite_signal(signals[VEHICLE_SPEED])
        return Signal("road_speed_ms", s.t, s.values / 3.6, "m/s"), "vehicle_speed"
    wheels = [finite_signal(signals[k]) for k in sorted(signals)
              if k.startswith(WHEEL_PREFIX) and k not in computed and len(finite_signal(signals[k])) > 8]
    if not wheels or not wheel_radius_m:
        return None
    t = wheels[0].t
    mean = np.mean([w.at(t) for w in wheels], axis=0)
    ok = np.isfinite(mean)
    return Signal("road_speed_ms", t[ok], rpm_to_rad_s(mean[ok]) * wheel_radius_m, "m/s"), "wheel_speed"


def _saturation(values: FloatArray, t: FloatArray) -> tuple[tuple[float, float], ...]:
    runs: list[tuple[float, float]] = []
    for extreme in (float(np.max(values)), float(np.min(values))):
        at = np.isclose(values, extreme, rtol=0, atol=1e-9 + 1e-6 * abs(extreme))
        if at.sum() < SATURATION_RUN or extreme == 0.0:
            continue
        edges = np.diff(np.concatenate(([0], at.astype(np.int8), [0])))
        starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0]
        runs += [(float(t[a]), float(t[b - 1])) for a, b in zip(starts, stops, strict=True)
                 if b - a >= SATURATION_RUN]
    return tuple(sorted(runs))


def check_accelerometer(accel: Signal, road: Signal | None) -> AccelCheck:
    """Slope, offset and saturation of an accelerometer against the road speed (module docstring)."""
    s = finite_signal(accel)
    sat = _saturation(s.values, s.t) if len(s) else ()
    if road is None or len(s) < 16 or len(road) < 16:
        return AccelCheck("unchecked", saturated=sat)
    t, v = uniform(road)
    h = float(t[1] - t[0])
    n = max(1, round(CHECK_AVERAGE_S / h))
    kernel = np.ones(n) / n
    dvdt = np.convolve(np.gradient(v, h), kernel, mode="same")
    ta = np.convolve(s.at(t), kernel, mode="same")
    ok = np.isfinite(ta) & np.isfinite(dvdt)
    ok[: n] = ok[-n:] = False
    if sat:
        for t0, t1 in sat:
            ok &= ~((t >= t0 - CHECK_AVERAGE_S) & (t <= t1 + CHECK_AVERAGE_S))
    if ok.sum() < 4 * n or float(np.std(dvdt[ok])) < MIN_CHECK_STD:
        return AccelCheck("unchecked", saturated=sat)
    slope, offset = np.polyfit(dvdt[ok], ta[ok], 1)
    slope, offset = float(slope), float(offset)
    if abs(slope - 1.0) <= 0.3:
        verdict = "ok"
    elif abs(slope + 1.0) <= 0.3:
        verdict = "sign"
    elif abs(slope * G - 1.0) <= 0.3:
        verdict = "unit_g"
    elif abs(slope / G - 1.0) <= 0.3:
        verdict = "unit_ms2"
    else:
        verdict = "inconsistent"
    return AccelCheck(verdict, slope, offset, sat)


def _finding(chk: AccelCheck) -> Finding | None:
    msg = {
        "sign": (ACCEL_SIGN, f"the accelerometer reads {chk.slope:.2f} x the road speed's derivative: its sign is "
                             "inverted (set invert = true in the signal map); criteria taken from the road speed"),
        "unit_g": (ACCEL_UNIT, f"the accelerometer reads {chk.slope:.3f} x the road speed's derivative: it carries g "
                               "declared as m/s^2 (set unit = \"g\"); criteria taken from the road speed"),
        "unit_ms2": (ACCEL_UNIT, f"the accelerometer reads {chk.slope:.1f} x the road speed's derivative: it carries "
                                 "m/s^2 declared as g; criteria taken from the road speed"),
        "inconsistent": (ACCEL_INCONSISTENT, f"the accelerometer reads {chk.slope:.2f} x the road speed's "
                                             "derivative (expected 1): wrong factor or axis; criteria taken from "
                                             "the road speed"),
    }.get(chk.verdict)
    return Finding(msg[0], ACCEL, msg[1]) if msg else None


def acceleration_source(signals: SignalSet, wheel_radius_m: float | None, cutoff_hz: float,
                        computed: frozenset[str] = frozenset()) -> AccelSource | None:
    """The log's acceleration: the checked accelerometer, else derived from the road speed; None without both."""
    road = road_speed(signals, wheel_radius_m, computed)
    findings: list[Finding] = []
    note = ""
    if ACCEL in signals and len(finite_signal(signals[ACCEL])) >= 16:
        acc = finite_signal(signals[ACCEL])
        chk = check_accelerometer(acc, road[0] if road else None)
        if chk.saturated:
            lo, hi = float(np.min(acc.values)), float(np.max(acc.values))
            findings.append(Finding(ACCEL_SATURATED, ACCEL,
                                    f"the accelerometer sits at its range ({lo:g} / {hi:g} m/s^2) in "
                                    f"{len(chk.saturated)} runs of {SATURATION_RUN}+ samples; criteria of those "
                                    "events are left out"))
        bad = _finding(chk)
        if bad is None:
            t, a = uniform(acc)
            if math.isfinite(chk.offset_ms2):
                a = a - chk.offset_ms2
            return AccelSource(t, a, "accelerometer", math.inf, chk, findings,
                               "offset removed" if math.isfinite(chk.offset_ms2) else "offset not known")
        findings.append(bad)
        note = f"accelerometer rejected ({chk.verdict})"
        rejected: AccelCheck | None = chk
    else:
        rejected = None
    if road is None:
        return None
    t, v = uniform(road[0])
    a, bw = derive(t, v, cutoff_hz)
    fs = float(f"{1.0 / float(t[1] - t[0]):.6g}")
    noise = noise_rms(v) * derivative_noise_gain(fs, cutoff_hz)
    return AccelSource(t, a, road[1], bw, rejected, findings, note, noise)
