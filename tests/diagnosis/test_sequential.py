"""The sequential design: stratified stages whose decision must agree before the design stops adding events."""

from __future__ import annotations

import itertools
from collections.abc import Callable

import numpy as np
import pytest

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals
from app.analysis.diagnosis.split import make_split, restricted, spread_order, stage_sizes, stratified_order
from app.errors import InputError
from app.progress import ETA_MIN_FRACTION
from app.signals import SignalSet
from tests.diagnosis.conftest import paper
from tests.diagnosis.test_split import Ev


def _events(n_in: int, n_out: int) -> list[Ev]:
    rng = np.random.default_rng(3)
    kinds = ["tip_in"] * n_in + ["tip_out"] * n_out
    return [Ev(i, k, float(i), float(rng.uniform(500, 5000)), float(rng.uniform(-200, 200)))
            for i, k in enumerate(kinds)]


def test_spread_order_is_a_permutation_whose_prefixes_span_the_range() -> None:
    for m in (1, 2, 7, 24, 100):
        order = spread_order(m)
        assert sorted(order) == list(range(m))
    order = spread_order(100)
    assert order[:4] == [0, 50, 25, 75]
    # every prefix of 8 leaves no gap of more than a quarter of the range
    gaps = np.diff(sorted([0, *order[:8], 99]))
    assert gaps.max() <= 25


def test_stratified_order_takes_kinds_in_proportion_and_spans_their_speeds() -> None:
    events = _events(60, 30)
    order = stratified_order(events)
    assert sorted(e.index for e in order) == list(range(90))
    for n in (6, 12, 24, 48):
        ins = sum(e.kind == "tip_in" for e in order[:n])
        assert abs(ins - 2 * n / 3) <= 1, (n, ins)
    speeds = sorted(e.speed_rpm for e in events if e.kind == "tip_in")
    first = [e.speed_rpm for e in order[:12] if e.kind == "tip_in"]
    assert min(first) <= speeds[len(speeds) // 8] and max(first) >= speeds[-len(speeds) // 8]


def test_stage_sizes_double_until_a_stage_would_take_most_of_a_side() -> None:
    assert stage_sizes(23) == [23]
    assert stage_sizes(32) == [32]  # 24 is 75 % of it: one stage of all events, as a 60 s drive
    assert stage_sizes(72) == [24, 48, 72]
    assert stage_sizes(215) == [24, 48, 96, 215]
    assert stage_sizes(40, first=8) == [8, 16, 40]


def test_restricted_split_keeps_each_event_on_its_side_with_its_own_digest() -> None:
    events = _events(40, 40)
    split = make_split(events, seed=5)
    sub = stratified_order(split.calibration_events(events))[:10] + stratified_order(split.heldout_events(events))[:10]
    part = restricted(split, sub)
    assert set(part.calibration) <= set(split.calibration) and set(part.heldout) <= set(split.heldout)
    assert len(part.calibration) == 10 and len(part.heldout) == 10
    assert part.digest != split.digest
    assert restricted(split, events).digest == split.digest


def test_stage_events_below_the_decision_minimum_is_refused() -> None:
    with pytest.raises(InputError, match="stage_events"):
        DiagnosisOptions(stage_events=1)


def test_staged_diagnosis_stops_when_two_stages_agree_and_matches_all_events(
        signals_for: Callable[..., SignalSet]) -> None:
    """A clear torque lag over a 120 s drive (about 18 events per side), with stages of 4, 8, ... events per side:
    the design stops once two stages agree, says which events it did not need and why, and names what the
    one-stage diagnosis names."""
    sig = signals_for("torque_lag", (("tau_s", 0.015), ("delay_s", 0.0)), 21, 120.0)
    base = dict(candidates=("torque_lag", "drag"), seed=2, max_pairs=0)
    reports: list[tuple[float, str]] = []
    staged = diagnose_signals(sig, paper(), DiagnosisOptions(**base, stage_events=4),  # type: ignore[arg-type]
                              progress=lambda f, m: reports.append((f, m)))
    said = [m for _, m in reports]
    whole = diagnose_signals(sig, paper(), DiagnosisOptions(**base, sequential=False))  # type: ignore[arg-type]
    assert whole.decision.status == "explained" and whole.decision.top == ("torque_lag",)
    assert (staged.decision.status, staged.decision.top) == (whole.decision.status, whole.decision.top)
    assert staged.fit_order[0].startswith("sequential design (events per side: decision): 4: ")
    assert "stable, stopped" in staged.fit_order[0]
    left = [s for s in staged.skipped if "sequential design stopped" in str(s["reason"])]
    assert left and len(staged.events) + len(left) == len(whole.events)
    assert len(staged.split.calibration) < len(whole.split.calibration)
    assert any(m.startswith("stage 2 (8 events per side)") for m in said)
    # the fractions only grow and end at 1, so the time left the command line and the job status derive from
    # them (app.progress.eta_seconds) is the pace of the whole staged run
    fractions = [f for f, _ in reports]
    assert all(0.0 <= a <= b <= 1.0 for a, b in itertools.pairwise(fractions))
    assert fractions[-1] == 1.0 and sum(ETA_MIN_FRACTION <= f < 1.0 for f in fractions) >= 5


def test_clusters_simulated_side_by_side_give_the_serial_result(signals_for: Callable[..., SignalSet],
                                                                 monkeypatch: pytest.MonkeyPatch) -> None:
    """The integrator runs without the interpreter lock, so the clusters of a pass run on threads; the outputs are
    the serial ones, bit for bit and in the events' order."""
    import app.analysis.diagnosis.forward as forward
    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
    from app.analysis.events import detect_events

    sig = signals_for("drag", (("coulomb_nm", 3.0), ("viscous_nms", 0.005)), 5, 60.0)
    events, _, _ = prepare(sig, detect_events(sig, DIAGNOSIS_EVENTS))
    assert len(forward.clusters(events)) > 2
    monkeypatch.setattr(forward, "SIM_THREADS", 1)
    serial = forward.simulate_events(events, paper(), 0.97)
    monkeypatch.setattr(forward, "SIM_THREADS", 3)
    threaded = forward.simulate_events(events, paper(), 0.97)
    assert len(serial) == len(threaded) == len(events)
    for a, b in zip(serial, threaded, strict=True):
        np.testing.assert_array_equal(a.t, b.t)
        np.testing.assert_array_equal(a.speed, b.speed)


def test_stage_starts_key_fits_by_their_effects_and_order_and_turn_over_per_stage() -> None:
    from app.analysis.diagnosis.calibrate import StageStarts

    memory = StageStarts()
    assert memory.claim(("drag",)) == ((("drag",), 0), None)
    assert memory.claim(("drag",))[0] == (("drag",), 1)
    assert memory.claim(("backlash", "drag"))[0] == (("backlash", "drag"), 0)
    memory.current[(("drag",), 1)] = "end"  # type: ignore[assignment]
    memory.next_stage()
    assert memory.claim(("drag",)) == ((("drag",), 0), None)
    assert memory.claim(("drag",)) == ((("drag",), 1), "end")
    assert memory.current == {}


def test_a_stage_refines_its_fits_from_where_the_previous_stage_ended(signals_for: Callable[..., SignalSet]) -> None:
    """The second stage's fit of the drag (on the first stage's events and as many again) screens the first
    stage's end point with its own starts: it ends where the fit without it ends, or lower, for fewer passes.
    Outside ``stage_starts`` nothing is kept."""
    from app.analysis.diagnosis.calibrate import Bounds, fit, stage_starts
    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
    from app.analysis.events import detect_events
    from sim.effects import get_effect

    sig = signals_for("drag", (("coulomb_nm", 3.0), ("viscous_nms", 0.005)), 5, 120.0)
    events, noise, _ = prepare(sig, detect_events(sig, DIAGNOSIS_EVENTS))
    split = make_split(events, 1)
    cal = stratified_order(split.calibration_events(events))
    first, second = cal[:len(cal) // 2], cal
    assert len(first) >= 6
    bounds = Bounds.for_period(noise.period_s)
    drag = (get_effect("drag"),)
    cold = fit(paper(), second, restricted(split, second), drag, bounds=bounds, seed=2)
    with stage_starts() as memory:
        memory.next_stage()
        one = fit(paper(), first, restricted(split, first), drag, bounds=bounds, seed=2)
        memory.next_stage()
        two = fit(paper(), second, restricted(split, second), drag, bounds=bounds, seed=2)
    assert memory.previous[(("drag",), 0)] is one and memory.current[(("drag",), 0)] is two
    assert two.chi2 <= cold.chi2 * 1.001, (two.chi2, cold.chi2)
    assert two.nfev < cold.nfev, (two.nfev, cold.nfev)
    for name, value in cold.values["drag"].items():
        assert two.values["drag"][name] == pytest.approx(value, rel=0.05, abs=1e-4), name
    again = fit(paper(), second, restricted(split, second), drag, bounds=bounds, seed=2)
    assert (again.chi2, again.nfev) == (cold.chi2, cold.nfev)
