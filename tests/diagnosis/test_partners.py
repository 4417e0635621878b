"""The partner screen: what each candidate could add to the best single fit, to first order."""

from __future__ import annotations

from functools import cache

import numpy as np

from app.analysis.diagnosis.calibrate import Bounds, fit
from app.analysis.diagnosis.partners import screen_partners
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.diagnosis.split import make_split
from app.analysis.diagnosis.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals
from app.analysis.events import detect_events
from sim.effects import apply_effects, get_effect
from tests.diagnosis.conftest import paper

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
    return cal, fit(v, cal, split, (get_effect("backlash"),), bounds=bounds, start=base)


def test_the_effect_left_in_the_remainder_ranks_first_with_a_start_near_its_value() -> None:
    cal, first = first_fit()
    screen = screen_partners(paper(), cal, first, ["torque_lag", "drag", "housing_mount", "speed_sensor"],
                             "multibody")
    assert screen[0].id == "drag"
    assert screen[0].gain > 2 * max(s.gain for s in screen[1:])
    assert screen[0].gain < first.chi2  # a share of what the first fit leaves, never more
    assert 1.0 < screen[0].start["coulomb_nm"] <= 6.0
    assert [s.gain for s in screen] == sorted((s.gain for s in screen), reverse=True)


def test_a_partner_whose_signature_the_remainder_lacks_gains_little() -> None:
    """What a sensor filter could remove of the lash fit's remainder is a small fraction of the drag's: its
    signature is not what is left (the nuisance columns take what any time shift would)."""
    cal, first = first_fit()
    (s,) = screen_partners(paper(), cal, first, ["speed_sensor"], "multibody")
    drag = screen_partners(paper(), cal, first, ["drag"], "multibody")[0]
    assert s.gain < 0.2 * drag.gain
