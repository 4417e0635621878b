"""The acceleration channel: checked against the road speed (unit, sign, saturation), or derived from it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.accel import (
    ACCEL,
    acceleration_source,
    check_accelerometer,
    derivative_bandwidth,
    derive,
    road_speed,
)
from app.signals import Signal, SignalSet

G = 9.80665


def drive(duration: float = 40.0, dt: float = 0.001) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Road speed (m/s) and acceleration (m/s^2): accelerate, brake, with a 5 Hz shuffle on top."""
    t = np.arange(0.0, duration, dt)
    base = 1.5 * np.sin(2 * np.pi * t / 10.0)  # +-1.5 m/s^2 every 10 s
    shuffle = 0.4 * np.sin(2 * np.pi * 5.0 * t)
    a = base + shuffle
    v = 10.0 + np.cumsum(a) * dt
    return t, v, a


def signals(t: np.ndarray, v: np.ndarray, accel: np.ndarray | None, period: float = 0.01,
            speed_channel: str = "vehicle_speed_kmh") -> SignalSet:
    ss = SignalSet()
    k = max(1, round(period / (t[1] - t[0])))
    if speed_channel == "vehicle_speed_kmh":
        ss.add(Signal("vehicle_speed_kmh", t[::k], v[::k] * 3.6, "km/h"))
    else:
        rpm = v / 0.3 * 30 / math.pi
        for w in ("fl", "fr", "rl", "rr"):
            ss.add(Signal(f"wheel_speed_{w}_rpm", t[::k], rpm[::k], "rpm"))
    if accel is not None:
        ss.add(Signal(ACCEL, t[::10], accel[::10], "m/s^2"))
    return ss


@pytest.mark.parametrize(("factor", "verdict"), [(1.0, "ok"), (-1.0, "sign"), (1 / G, "unit_g"), (G, "unit_ms2"),
                                                 (0.5, "inconsistent")])
def test_the_check_tells_unit_and_sign_from_the_road_speed(factor: float, verdict: str) -> None:
    t, v, a = drive()
    road = Signal("road", t[::10], v[::10], "m/s")
    chk = check_accelerometer(Signal(ACCEL, t[::10], factor * a[::10] + 0.2, "m/s^2"), road)
    assert chk.verdict == verdict
    assert chk.slope == pytest.approx(factor, rel=0.05)


def test_offset_is_measured_and_removed() -> None:
    t, v, a = drive()
    src = acceleration_source(signals(t, v, a + 0.25), None, 15.0)
    assert src is not None and src.kind == "accelerometer" and src.check is not None
    assert src.check.offset_ms2 == pytest.approx(0.25, abs=0.03)
    assert float(np.median(src.a - np.interp(src.t, t, a))) == pytest.approx(0.0, abs=0.03)
    assert math.isinf(src.bandwidth_hz) and not src.findings


def test_a_wrong_sign_is_a_finding_and_the_road_speed_is_used() -> None:
    t, v, a = drive()
    src = acceleration_source(signals(t, v, -a), None, 15.0)
    assert src is not None and src.kind == "vehicle_speed"
    assert [f.code for f in src.findings] == ["accel_sign"]
    assert "invert = true" in src.findings[0].message
    assert src.note == "accelerometer rejected (sign)"


def test_saturation_is_found_and_marks_the_windows() -> None:
    t, v, a = drive()
    clipped = np.clip(a, -1.2, 1.2)
    src = acceleration_source(signals(t, v, clipped), None, 15.0)
    assert src is not None and src.kind == "accelerometer" and src.check is not None
    assert "accel_saturated" in [f.code for f in src.findings]
    t0, t1 = src.check.saturated[0]
    assert src.saturated_in(t0 - 0.1, t1 + 0.1)
    assert not src.saturated_in(0.0, 0.3)  # |a| <= 0.4 m/s^2 there: the road acceleration starts at 0


def test_derived_acceleration_follows_the_shuffle_with_its_bandwidth() -> None:
    t, v, a = drive()
    src = acceleration_source(signals(t, v, None, period=0.02), None, 15.0)
    assert src is not None and src.kind == "vehicle_speed"
    assert src.bandwidth_hz == pytest.approx(derivative_bandwidth(50.0, 15.0), rel=1e-9)
    assert 10.0 < src.bandwidth_hz < 15.0
    m = (src.t > 2) & (src.t < 38)
    err = src.a[m] - np.interp(src.t[m], t, a)
    assert float(np.sqrt(np.mean(err**2))) < 0.05  # the 5 Hz shuffle passes within a few %


def test_wheel_speeds_need_the_tyre_radius() -> None:
    t, v, _ = drive(10.0)
    ss = signals(t, v, None, speed_channel="wheels")
    assert road_speed(ss, None) is None
    sig, kind = road_speed(ss, 0.3) or (None, "")
    assert kind == "wheel_speed" and sig is not None
    assert float(np.median(sig.values)) == pytest.approx(float(np.median(v)), rel=1e-3)


def test_no_accelerometer_and_no_road_speed_gives_none() -> None:
    assert acceleration_source(SignalSet(), 0.3, 15.0) is None


def test_five_point_derivative_is_exact_for_a_cubic() -> None:
    t = np.arange(0.0, 1.0, 0.01)
    v = 2 * t**3 - t + 1
    a, bw = derive(t, v, cutoff_hz=40.0)  # the low pass is clipped to 0.4 fs = 40 Hz
    mid = slice(20, 80)
    assert np.allclose(a[mid], 6 * t[mid] ** 2 - 1, atol=2e-3)
    assert bw > 20.0
