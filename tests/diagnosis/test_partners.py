"""The partner screen: what each candidate could add to the best single fit, to first order."""

from __future__ import annotations

from dataclasses import replace
from functools import cache

import numpy as np
import pytest

from app.analysis.diagnosis.calibrate import Bounds, fit
from app.analysis.diagnosis.partners import screen_partners
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.diagnosis.split import make_split
from app.analysis.events import detect_events
from sim.effects import apply_effects, get_effect
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

TRUTH = {"backlash": {"reducer_scale": 1.8, "halfshaft_scale": 1.0}, "drag": {"coulomb_nm": 4.0, "viscous_nms": 0.01}}


@cache
def first_fit():  # type: ignore[no-untyped-def]
    """Calibration events of a drive with extra lash and a drag, and the fit of the lash alone."""
    v = paper()
    rng = np.random.default_rng(21)
    drive = make_drive(v, rng, DriveSpec(duration_s=30.0))
    signals = to_signals(measure(drive, run_truth(apply_effects(v, TRUTH), drive), CanSampling(), rng))
    events, noise, _ = prepare(signals, detect_events(signals, DIAGNOSIS_EVENTS))
    split = make_split(events, seed=1)
    cal = split.calibration_events(events)
    bounds = Bounds.for_period(noise.period_s)
    base = fit(v, cal, split, (), bounds=bounds)
    return cal, fit(v, cal, split, (get_effect("backlash"),), bounds=bounds, start=base), split, bounds


def test_the_effect_left_in_the_remainder_ranks_first_with_a_start_near_its_value() -> None:
    cal, first, *_ = first_fit()
    screen = screen_partners(paper(), cal, first, ["torque_lag", "drag", "housing_mount", "speed_sensor"],
                             "multibody")
    assert screen[0].id == "drag"
    assert screen[0].gain > 2 * max(s.gain for s in screen[1:])
    assert screen[0].gain < first.chi2  # a share of what the first fit leaves, never more
    lin, third, tenth = (st["coulomb_nm"] for st in screen[0].starts)
    assert 1.0 < lin <= 6.0 and third == pytest.approx(0.3 * lin) and tenth == pytest.approx(0.1 * lin)
    assert [s.gain for s in screen] == sorted((s.gain for s in screen), reverse=True)


def test_a_partner_whose_signature_the_remainder_lacks_gains_little() -> None:
    """What a sensor filter could remove of the lash fit's remainder is a small fraction of the drag's: its
    signature is not what is left (the nuisance columns take what any time shift would)."""
    cal, first, *_ = first_fit()
    (s,) = screen_partners(paper(), cal, first, ["speed_sensor"], "multibody")
    drag = screen_partners(paper(), cal, first, ["drag"], "multibody")[0]
    assert s.gain < 0.2 * drag.gain


def test_a_refinement_stops_at_its_pass_budget_with_the_best_point_seen() -> None:
    """Jacobian passes count against the budget; the result is the best point seen, with the trade-off test
    made on a Jacobian taken there."""
    cal, first, split, bounds = first_fit()
    effects = (get_effect("backlash"), get_effect("drag"))
    start = {"backlash": first.values["backlash"], "drag": {"coulomb_nm": 0.5, "viscous_nms": 0.001}}
    short = fit(paper(), cal, split, effects, bounds=bounds, start=replace(first, values=start),
                screen=False, max_passes=8)
    assert "pass budget" in short.message
    assert short.nfev <= 1 + 8 + 6 + 2  # the start, the budget, one Jacobian, the final pass (and its repeat)
    full = fit(paper(), cal, split, effects, bounds=bounds, start=replace(first, values=start),
               screen=False)
    assert "pass budget" not in full.message
    assert full.chi2 <= short.chi2 < first.chi2  # the drag lowers it at once; the full refinement further


@cache
def lagged_baseline():  # type: ignore[no-untyped-def]
    """Calibration events of a drive whose torque reaches the shafts 35 ms late (a 20 ms delay and a 15 ms lag),
    beyond the time offset's +-20 ms, and the baseline fit (its offset on the bound)."""
    v = paper()
    rng = np.random.default_rng(23)
    drive = make_drive(v, rng, DriveSpec(duration_s=30.0))
    lag = {"torque_lag": {"tau_s": 0.015, "delay_s": 0.02}}
    signals = to_signals(measure(drive, run_truth(apply_effects(v, lag), drive), CanSampling(), rng))
    events, noise, _ = prepare(signals, detect_events(signals, DIAGNOSIS_EVENTS))
    split = make_split(events, seed=1)
    cal = split.calibration_events(events)
    bounds = Bounds.for_period(noise.period_s)
    return cal, fit(v, cal, split, (), bounds=bounds), bounds


def test_the_screen_moves_the_nuisance_only_as_far_as_a_fit_could() -> None:
    """With the time offset on its bound, the lag beyond it is the lag's to take: unbounded, the offset's column
    carries the delay past the bound to first order and the lag screens as a fraction of what it removes."""
    cal, base, bounds = lagged_baseline()
    assert base.nuisance.offset_s == pytest.approx(bounds.offset_s[1], abs=1e-3)
    (free,) = screen_partners(paper(), cal, base, ["torque_lag"], "multibody")
    (held,) = screen_partners(paper(), cal, base, ["torque_lag"], "multibody", bounds)
    assert held.gain > 2.5 * free.gain  # 1.59e6 against 0.49e6 on this drive
    assert held.gain > 0.8 * base.chi2  # nearly all the baseline leaves is the lag beyond the offset
    lin = held.starts[0]
    assert lin["tau_s"] + lin["delay_s"] > 0.005  # the start moves the lag towards the truth
