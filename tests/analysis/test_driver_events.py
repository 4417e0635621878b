"""Events a driver makes: tip-in from a coast at 0 N m and from regeneration, tip-out to coast,
inverter ringing rejected, wheel slip excluded. Synthetic torque traces, fixed seeds."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.events import EventKind, EventParams, detect_events, find_events
from app.analysis.slip import Drive
from app.signals import Signal, SignalSet

RATIO = 10.0
RADIUS = 0.25
DT = 0.01


def _ramp(t: np.ndarray, t0: float, a: float, b: float, rate: float) -> np.ndarray:
    return np.asarray(a + (b - a) * np.clip((t - t0) * rate / abs(b - a), 0.0, 1.0))


def _set(t: np.ndarray, tq: np.ndarray, motor_rpm: np.ndarray | None = None,
         wheel_rpm: np.ndarray | None = None, pedal: np.ndarray | None = None) -> SignalSet:
    ss = SignalSet()
    ss.add(Signal.from_samples("motor_torque_nm", t, tq, "Nm"))
    ss.add(Signal.from_samples("motor_speed_rpm", t, np.full(t.size, 3000.0) if motor_rpm is None else motor_rpm,
                               "rpm"))
    if wheel_rpm is not None:
        for w in ("fl", "fr"):
            ss.add(Signal.from_samples(f"wheel_speed_{w}_rpm", t, wheel_rpm, "rpm"))
    if pedal is not None:
        ss.add(Signal.from_samples("pedal_pct", t, pedal, "%"))
    return ss


def _coast_drive(seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Coast at exactly 0 N m, tip-in at 2.0 s (0 -> 80 N m at 800 N m/s), tip-out to coast at 5.0 s."""
    t = np.arange(0.0, 8.0, DT)
    tq = _ramp(t, 2.0, 0.0, 80.0, 800.0)
    tq = np.where(t >= 5.0, _ramp(t, 5.0, 80.0, 0.0, 1000.0), tq)
    noise = np.random.default_rng(seed).normal(0.0, 0.3, t.size)
    return t, np.where(tq > 0, tq + noise, 0.0)  # the inverter reports exactly 0 while coasting


def test_tip_in_from_a_coast_at_zero_and_tip_out_to_coast_are_found_with_timing_and_rate() -> None:
    t, tq = _coast_drive()
    ev = detect_events(_set(t, tq))
    assert [e.kind for e in ev] == [EventKind.TIP_IN, EventKind.TIP_OUT]
    tip_in, tip_out = ev
    assert tip_in.from_coast and tip_out.from_coast
    assert tip_in.t_cross_s == pytest.approx(2.0, abs=DT)  # the last sample at 0 N m: where the ramp starts
    assert tip_in.torque_rate_nm_s == pytest.approx(800.0, rel=0.15)
    assert tip_in.torque_before_nm == 0.0 and tip_in.torque_after_nm == pytest.approx(80.0, abs=1.0)
    assert tip_out.t_cross_s == pytest.approx(5.08, abs=DT)  # where the torque reaches 0
    assert tip_out.torque_rate_nm_s == pytest.approx(-1000.0, rel=0.15)
    assert all(e.included for e in ev)


def test_tip_in_from_regeneration_is_found_and_not_marked_as_coast() -> None:
    t = np.arange(0.0, 6.0, DT)
    tq = _ramp(t, 2.0, -50.0, 150.0, 1500.0) + np.random.default_rng(5).normal(0.0, 0.3, t.size)
    (e,) = detect_events(_set(t, tq))
    assert e.kind is EventKind.TIP_IN and not e.from_coast
    assert e.t_cross_s == pytest.approx(2.0 + 50.0 / 1500.0, abs=0.004)
    assert e.torque_rate_nm_s == pytest.approx(1500.0, rel=0.1)


def _ringing(t: np.ndarray, t0: float, t1: float, amp: float = 15.0, hz: float = 25.0) -> np.ndarray:
    """The inverter's torque ringing around 0 N m while coasting (no driver input)."""
    return np.where((t >= t0) & (t < t1), amp * np.sin(2 * np.pi * hz * (t - t0)), 0.0)


def test_inverter_ringing_around_zero_is_rejected_and_counted() -> None:
    t = np.arange(0.0, 6.0, DT)
    tq = _ringing(t, 1.0, 4.0)
    det = find_events(_set(t, tq))
    assert det.events == []
    assert det.ringing >= 20  # every excursion above +5 N m that did not dwell
    # a driver pumping the pedal at 1 Hz holds each side for 0.5 s: those are events (3 tip-ins, 3 tip-outs)
    pumping = find_events(_set(t, np.where((t >= 1.0) & (t < 4.0), 60.0 * np.sin(2 * np.pi * (t - 1.0)), 0.0)))
    assert [e.kind.value for e in pumping.events] == ["tip_in", "tip_out"] * 3
    assert pumping.ringing == 0


def test_a_real_tip_in_out_of_a_ringing_coast_is_still_found() -> None:
    t = np.arange(0.0, 8.0, DT)
    tq = _ringing(t, 1.0, 3.0) + _ramp(t, 3.0, 0.0, 90.0, 900.0)
    ev = detect_events(_set(t, tq))
    assert [e.kind for e in ev] == [EventKind.TIP_IN]
    assert ev[0].t_cross_s == pytest.approx(3.0, abs=0.02) and ev[0].from_coast


def test_a_tip_in_whose_torque_rings_through_the_crossing_is_rejected() -> None:
    t = np.arange(0.0, 6.0, 0.002)
    tq = _ramp(t, 2.0, 0.0, 80.0, 800.0)
    tq = tq + np.where(np.abs(t - 2.02) < 0.02, 30.0 * np.sin(2 * np.pi * 50.0 * (t - 2.0)), 0.0)
    det = find_events(_set(t, np.maximum(tq, -20.0)))
    assert det.events == [] and det.ringing >= 1


def test_dwell_is_settable_and_pedal_confirmation_applies_to_coast_tip_ins() -> None:
    t, tq = _coast_drive()
    # a 3 s drive phase is no event when each side must dwell 4 s
    assert detect_events(_set(t, tq), EventParams(min_dwell_s=4.0)) == []
    pedal = np.where((t > 1.9) & (t < 4.9), 30.0, 0.0)
    ev = detect_events(_set(t, tq, pedal=pedal))
    assert [e.pedal_corroborated for e in ev] == [True, True] and all(e.included for e in ev)
    ev = detect_events(_set(t, tq, pedal=np.full(t.size, 10.0)))
    assert [e.exclusion.split(":")[0] for e in ev if e.exclusion] == ["pedal does not corroborate the tip_in",
                                                                     "pedal does not corroborate the tip_out"]


def test_wheel_spin_after_a_tip_in_excludes_the_event_with_the_slip_value() -> None:
    t, tq = _coast_drive()
    wheel = np.full(t.size, 300.0)  # rpm: 28 km/h with a 0.25 m tyre
    motor = wheel * RATIO + np.where(t > 2.1, np.minimum((t - 2.1) * 3000.0, 1200.0), 0.0)  # spins up by 40 %
    ev = detect_events(_set(t, tq, motor, wheel), drive=Drive(RATIO, RADIUS))
    reason = ev[0].exclusion or ""
    assert reason.startswith("wheel slip: motor speed 4200 rpm vs 3000 rpm")
    assert "(+40 %, limit ±15 %)" in reason
    # without the drive's ratio the slip cannot be judged: the event stays in
    assert detect_events(_set(t, tq, motor, wheel))[0].included


def test_shuffle_swinging_the_motor_against_the_wheels_is_not_slip() -> None:
    t, tq = _coast_drive()
    wheel = np.full(t.size, 300.0)
    # a 7 Hz shuffle of ±25 % decaying over a second: large for a moment, zero on average
    shuffle = np.where(t > 2.0, 750.0 * np.exp(-(t - 2.0) * 3.0) * np.sin(2 * np.pi * 7.0 * (t - 2.0)), 0.0)
    ev = detect_events(_set(t, tq, wheel * RATIO + shuffle, wheel), drive=Drive(RATIO, RADIUS))
    assert ev[0].included, ev[0].exclusion


def test_slip_against_vehicle_speed_uses_the_tyre_radius() -> None:
    t, tq = _coast_drive()
    ss = _set(t, tq, np.full(t.size, 3600.0))
    v_kmh = 300.0 * 2 * np.pi / 60 * RADIUS * 3.6  # 300 rpm at the wheel = 3000 rpm at the motor
    ss.add(Signal.from_samples("vehicle_speed_kmh", t, np.full(t.size, v_kmh), "km/h"))
    reason = detect_events(ss, drive=Drive(RATIO, RADIUS))[0].exclusion or ""
    assert reason.startswith("wheel slip: motor speed 3600 rpm vs 3000 rpm from vehicle_speed_kmh")
    assert "(+20 %, limit ±15 %)" in reason


@pytest.mark.parametrize("field, value", [("min_dwell_s", -0.1), ("max_ramp_reversal", 1.5), ("max_wheel_slip", 0.0)])
def test_out_of_range_thresholds_are_refused(field: str, value: float) -> None:
    with pytest.raises(ValueError, match=f"EventParams.{field}"):
        EventParams(**{field: value})
