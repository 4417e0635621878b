"""Windows of a low-rate logger: cut short by the next reversal, or with a frame lost, they still hold enough to fit."""

from __future__ import annotations

from functools import cache

import numpy as np
import pytest

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, WindowParams, enough_samples, prepare
from app.analysis.events import TORQUE, EventParams, detect_events, gap_limit
from app.signals import Signal, SignalSet
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

QUICK = (0.6, 0.8)  # s between reversals: each window ends at the next one


@cache  # one drive per rate for the whole module: the tests only read it
def _signals(period_s: float, seed: int = 5) -> SignalSet:
    rng = np.random.default_rng(seed)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=40.0, hold_s=QUICK))
    return to_signals(measure(drive, run_truth(paper(), drive), CanSampling(period_s=period_s), rng))


def test_the_rule_counts_samples_and_how_far_past_the_crossing_they_reach() -> None:
    p = WindowParams()
    at20 = 10.0 + np.arange(-0.3, 0.5, 0.05)  # 16 samples, 0.45 s past a crossing at 10 s
    assert at20.size == 16 and enough_samples(at20, 10.0, p)
    assert not enough_samples(at20[:-2], 10.0, p)  # 14 samples, only 0.35 s past it
    assert not enough_samples(at20[:11], 10.0, p)  # 11 samples
    at100 = 10.0 + np.arange(-0.05, 0.1, 0.01)  # 15 samples at 100 Hz: 0.09 s of response is not enough
    assert not enough_samples(at100, 10.0, p)
    assert enough_samples(10.0 + np.arange(-0.05, 0.15, 0.01), 10.0, p)  # 20 samples, as before
    strict = WindowParams(min_samples_low_rate=20)
    assert not enough_samples(at20, 10.0, strict)


def test_a_20_hz_log_with_quick_reversals_keeps_its_events() -> None:
    sig = _signals(0.05)
    found = detect_events(sig, DIAGNOSIS_EVENTS)
    kept, _, skipped = prepare(sig, found)
    old, _, old_skipped = prepare(sig, found, WindowParams(min_samples_low_rate=20))
    assert len(found) >= 20
    assert len(old) <= 2 < 15 <= len(kept)  # the 20-sample rule alone leaves (almost) nothing at 20 Hz
    for ev in kept:
        assert ev.speed_t.size >= 12 and ev.speed_t[-1] - ev.t_event >= 0.4
    # what is still left out says what it lacked and what the rule needs
    reasons = [str(s["reason"]) for s in skipped if "too few samples" in str(s["reason"])]
    assert reasons and "or 12 reaching 0.4 s past the crossing" in reasons[0]
    assert len(skipped) < len(old_skipped)


def test_the_kept_events_diagnose_a_right_file_as_fitting() -> None:
    res = diagnose_signals(_signals(0.05), paper(), DiagnosisOptions(candidates=("drag",), seed=1, max_pairs=0))
    assert res.decision.status == "no_significant_gap", res.decision.reason
    assert len(res.events) >= 12


def _channel(period_s: float, duration_s: float = 10.0, drop_at: tuple[float, ...] = ()) -> Signal:
    t = np.arange(0.0, duration_s, period_s)
    keep = np.ones(t.size, dtype=bool)
    for at in drop_at:
        keep &= np.abs(t - at) > 1e-9 + 0.49 * period_s
    return Signal("motor_speed_rpm", t[keep], np.full(int(keep.sum()), 1000.0))


def test_one_lost_frame_of_a_slow_logger_is_not_missing_data() -> None:
    p = EventParams()
    assert gap_limit(_channel(0.01), p) == p.max_sample_gap_s  # 100 Hz: 0.1 s, ten lost frames
    assert gap_limit(_channel(0.05, drop_at=(5.0,)), p) == pytest.approx(0.125, rel=1e-2)  # 20 Hz, a frame lost
    assert gap_limit(_channel(0.1), p) == pytest.approx(0.25)  # 10 Hz: every spacing is 0.1 s
    # at 20 Hz one frame lost gives a 0.1 s gap (kept), three give 0.2 s (missing data)
    sig = _signals(0.05)
    tq = sig[TORQUE]
    events = [e for e in detect_events(sig, DIAGNOSIS_EVENTS) if e.included]
    assert events
    # an event with a torque sample past its crossing, and no frame lost around it, to take frames away at
    step = np.diff(tq.t)
    ev, at = next((e, i) for e in events
                  for i in np.flatnonzero((tq.t > e.t_cross_s + 0.05) & (tq.t < e.t_end_s - 0.25))
                  if step[i - 1:i + 4].max() < 0.07)
    for lost, kept in ((1, True), (3, False)):
        gone = np.zeros(tq.t.size, dtype=bool)
        gone[at:at + lost] = True
        holed = SignalSet({**{k: sig[k] for k in sig}, TORQUE: Signal(TORQUE, tq.t[~gone], tq.values[~gone])})
        same = min(detect_events(holed, DIAGNOSIS_EVENTS), key=lambda e: abs(e.t_cross_s - ev.t_cross_s))
        assert same.included is kept, same.exclusion
        if not kept:
            assert "gap" in str(same.exclusion) and "(over 0.1" in str(same.exclusion)
