from __future__ import annotations

import numpy as np
import pytest

from app.analysis.events import EventKind, EventParams, detect_events
from app.errors import MissingSignalError
from app.signals import Signal, SignalSet
from tests.analysis.synthetic import REVERSALS, drive


def test_finds_every_reversal_with_known_timing_rate_and_step() -> None:
    events = detect_events(drive())
    assert [e.kind for e in events] == [EventKind.TIP_IN, EventKind.TIP_OUT, EventKind.TIP_IN, EventKind.TIP_OUT]
    for ev, (tc, before, after, rate) in zip(events, REVERSALS, strict=True):
        assert ev.included, ev.exclusion
        assert ev.t_cross_s == pytest.approx(tc, abs=0.004)
        assert ev.torque_rate_nm_s == pytest.approx(rate, rel=0.05)
        assert ev.torque_before_nm == pytest.approx(before, abs=1.0)
        assert ev.torque_after_nm == pytest.approx(after, abs=1.0)
        assert ev.vehicle_speed_kmh == pytest.approx(25.0)
        assert ev.pedal_corroborated is True
        assert ev.t_start_s == pytest.approx(ev.t_cross_s - 0.5)
        assert ev.t_end_s <= ev.t_cross_s + 1.5 + 1e-9


def test_chatter_inside_the_hysteresis_band_and_small_steps_are_not_events() -> None:
    t = np.arange(0, 10, 0.01)
    rng = np.random.default_rng(1)
    ss = SignalSet()
    chatter = rng.uniform(-4.0, 4.0, t.size)  # inside ±5 Nm
    small = np.where(t < 5, -10.0, 10.0)  # crosses the band but the step is only 20 Nm
    ss.add(Signal.from_samples("motor_torque_nm", t, chatter + small))
    ss.add(Signal.from_samples("motor_speed_rpm", t, np.full_like(t, 2000.0)))
    assert detect_events(ss) == []
    assert len(detect_events(ss, EventParams(min_step_nm=15.0))) == 1


@pytest.mark.parametrize(
    ("kwargs", "index", "reason"),
    [
        ({"brake_at": 8.3}, 2, "braking: brake_pressed"),
        ({"speed_kmh": 1.5}, 0, "too low speed: vehicle speed 1.5 km/h"),
        ({"pedal_follows": False}, 1, "pedal does not corroborate the tip_out"),
        ({"speed_gap": (4.8, 5.2)}, 1, "missing data: motor_speed_rpm has a 0.4"),
    ],
)
def test_exclusions_say_why(kwargs: dict[str, object], index: int, reason: str) -> None:
    events = detect_events(drive(**kwargs))  # type: ignore[arg-type]
    assert len(events) == 4
    assert not events[index].included
    assert events[index].exclusion is not None and events[index].exclusion.startswith(reason)
    assert events[index].to_dict()["included"] is False


def test_a_brake_pressure_counts_from_its_resting_level() -> None:
    """A line-pressure sensor reads 10 psi with the foot off (its offset) and 12 psi with the foot resting on the
    pedal: neither is braking. A firm application (300 psi) inside the third event's window is. Measured from 0,
    every event would read as braked."""
    ss = drive()
    t = ss["motor_torque_nm"].t
    rng = np.random.default_rng(3)
    psi = 10.0 + rng.normal(0.0, 0.3, t.size) + np.where((t > 3.0) & (t < 4.0), 2.0, 0.0)
    psi = np.where(np.abs(t - 8.3) < 0.2, 300.0, psi)
    ss.add(Signal.from_samples("brake", t, psi, "psi"))
    events = detect_events(ss)
    assert [e.included for e in events] == [True, True, False, True]
    why = str(events[2].exclusion)
    assert why.startswith("braking: brake = 300 > 2") and "(resting level 9.5" in why


def test_brakes_applied_late_in_the_window_end_it_there() -> None:
    """A driver who lifts off and brakes 0.9 s later: the tip-out's response is logged before the brakes act, so
    the window ends at the brake application instead of the event being lost. Braking 0.3 s after the reversal
    (under ``min_post_s``) still excludes it."""
    t = drive()["motor_torque_nm"].t
    for lag, kept in ((0.9, True), (0.3, False)):
        ss = drive()
        ss.add(Signal.from_samples("brake", t, np.where((t > 5.0 + lag) & (t < 7.5), 250.0, 10.0), "psi"))
        ev = detect_events(ss)[1]
        assert ev.kind is EventKind.TIP_OUT and ev.included is kept, ev.exclusion
        if kept:
            assert ev.t_end_s == pytest.approx(5.0 + lag, abs=0.02)
        else:
            assert str(ev.exclusion).startswith("braking: brake = 250 >") and "+0.3" in str(ev.exclusion)


def test_next_reversal_too_close_cuts_the_window_and_excludes() -> None:
    events = detect_events(drive(duration=14.5), EventParams(post_s=2.9, min_post_s=2.8))
    assert all(not e.included and "window cut short" in str(e.exclusion) for e in events[:-1])
    assert events[-1].included


def test_without_pedal_and_vehicle_speed_channels_events_are_still_found() -> None:
    ss = drive()
    bare = SignalSet({k: v for k, v in ss.items() if k in ("motor_torque_nm", "motor_speed_rpm")})
    events = detect_events(bare)
    assert len(events) == 4 and all(e.included and e.pedal_corroborated is None for e in events)


def test_missing_torque_channel_is_a_typed_error() -> None:
    ss = drive()
    del ss.signals["motor_torque_nm"]
    with pytest.raises(MissingSignalError, match="motor_torque_nm"):
        detect_events(ss)


def test_window_beyond_the_end_of_the_log_is_missing_data() -> None:
    events = detect_events(drive(duration=12.0))
    assert events[-1].exclusion is not None and "does not cover the window" in events[-1].exclusion
