"""Identification before attribution (app/analysis/diagnosis/rebase.py) on drives with a known truth.

The truth is the simulator (these test the procedure; bench/identify_indep.py holds it to drives of an
independent model): a data sheet that is off is named as such and no effect is attributed; an effect on a car
whose data sheet is also off is named, with the base parameters refitted with it.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from app.analysis.diagnosis import DiagnosisOptions, augmented_vehicle, diagnose_signals, report_dict
from app.diagnosis_plots import chart_data
from app.identify import physical, with_base
from app.signals import SignalSet
from sim.effects import apply_effects
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals


def _drive(base: dict[str, float], effects: dict[str, dict[str, float]], seed: int) -> SignalSet:
    truth = apply_effects(with_base(paper(), base), effects) if effects else with_base(paper(), base)
    rng = np.random.default_rng(seed)
    drive = make_drive(paper(), rng, DriveSpec(duration_s=40.0))
    return to_signals(measure(drive, run_truth(truth, drive), CanSampling(offset_s=0.004), rng))


def test_a_data_sheet_that_is_off_is_named_and_nothing_is_attributed() -> None:
    res = diagnose_signals(_drive({"stiffness": 0.75, "mass": 1.15}, {}, 51), paper(), DiagnosisOptions(seed=0))
    d = res.decision
    assert d.status == "base_parameters" and d.top == ()
    items = {i["name"]: i for i in d.details["base_parameters"]}
    assert set(items) == {"stiffness", "mass"}
    assert items["stiffness"]["lo"] <= 0.75 <= items["stiffness"]["hi"]
    assert items["mass"]["ratio"] == pytest.approx(1.15, rel=0.03)
    assert "the vehicle file is off" in d.reason and "torsional stiffness at the motor 0.75x" in d.reason
    doc = report_dict(res)
    assert doc["identification"]["named"] == ["stiffness", "mass"]
    assert doc["decision"]["residual_to_noise_before"]["value"] > 10.0  # the file's vehicle, before
    # the charts: before is the file's vehicle, after the identified one, which leaves about the noise floor
    charts = chart_data(res)
    assert charts["fitted"] == "identified base parameters"
    assert [e["index"] for e in charts["events"]] == list(res.split.heldout)
    assert all(e["after"] < e["before"] for e in charts["events"])
    assert max(p["after"] for p in charts["phases"] if p["after"] is not None) < 3.0 < max(
        p["before"] for p in charts["phases"] if p["before"] is not None)
    # applying it gives the identified vehicle
    applied = augmented_vehicle(res, paper())
    assert physical(applied).stiffness_nm_rad == pytest.approx(0.75 * physical(paper()).stiffness_nm_rad, rel=0.03)


def test_an_effect_on_a_car_whose_data_sheet_is_off_is_still_named() -> None:
    res = diagnose_signals(_drive({"mass": 1.12}, {"torque_lag": {"tau_s": 0.02, "delay_s": 0.0}}, 52), paper(),
                           DiagnosisOptions(seed=0, candidates=("torque_lag", "speed_sensor", "drag", "backlash")))
    d = res.decision
    assert d.status in ("explained", "partial") and d.top == ("torque_lag",), d.reason
    # the lag is not taken by the base (the model-free mode holds stiffness and damping; a base that does not help
    # on held-out events alone is not the base the candidates start from), and no base parameter but the mass is
    # named with it
    assert res.identification is not None and res.identification.params["damping"].ratio == pytest.approx(1.0,
                                                                                                            abs=0.1)
    assert {i["name"] for i in d.details.get("base_parameters", [])} <= {"mass"}
    charts = chart_data(res)  # after: the named effect; its overlays end closer to the measured speed
    assert charts["fitted"] == "torque_lag" and len(charts["overlays"]) == min(12, len(res.split.heldout))
    o = charts["overlays"][0]
    sq = lambda a: sum((m - x) ** 2 for m, x in zip(o["measured_rpm"], a, strict=True))  # noqa: E731
    assert sq(o["fitted_rpm"]) < sq(o["baseline_rpm"])


def test_backlash_is_left_out_when_the_lash_traverse_falls_between_samples() -> None:
    """The chain-drive car logged at 20 Hz crosses its lash between two samples: where the lash sits cannot be
    told, so backlash is not a candidate (said why); at 100 Hz it is."""
    from sim import load_vehicle
    from tests.identify.drives import drive_signals
    from tests.support.synthetic import CanSampling

    why = {}
    for period in (0.05, 0.01):
        sig = drive_signals({}, seed=13, duration_s=60.0, vehicle="chain_drive",
                            sampling=CanSampling(period_s=period, jitter_s=0.001, drop_fraction=0.0))
        res = diagnose_signals(sig, load_vehicle("chain_drive"),
                               DiagnosisOptions(seed=0, candidates=("backlash", "torque_lag")))
        why[period] = report_dict(res)["candidates_not_applicable"]
    assert why[0.05]["backlash"].startswith("the lash traverse spans 0 speed samples in the median event (under 2)")
    assert "backlash" not in why[0.01]


def test_an_effect_that_trades_off_with_a_base_parameter_is_not_attributed() -> None:
    """A mount whose stiffness trades off with the identified chain stiffness in their joint fit: base_parameters,
    naming the trade-off; a trade-off between two effects' parameters, or an undecided answer, is left alone."""
    from dataclasses import replace

    from app.analysis.diagnosis.calibrate import FitResult
    from app.analysis.diagnosis.decide import Decision
    from app.analysis.diagnosis.forward import Nuisance
    from app.analysis.diagnosis.rebase import base_trade, not_separable
    from app.identify.fit import identify_events
    from sim import load_vehicle
    from tests.identify.drives import drive_signals, prepared

    fit = replace(FitResult(("base_stiffness", "housing_mount"), Nuisance(0.0, 1.0, 0.0), {}, 0.0, 0, 0),
                  trade_offs=(("base_stiffness.log2_scale", "housing_mount.stiffness_log2", -0.94),
                              ("housing_mount.damping_log2", "torque_lag.tau_s", 0.95)))
    partial = Decision("partial", top=("housing_mount",), reason="r")
    assert base_trade(partial, fit) == [("housing_mount.stiffness_log2", "base_stiffness.log2_scale", -0.94)]
    assert base_trade(replace(partial, status="ambiguous"), fit) == []
    assert base_trade(replace(partial, top=("torque_lag",)), fit) == []
    events, noise = prepared(drive_signals({"stiffness": 0.75}, seed=12, duration_s=40.0))
    ident = identify_events(events, noise, load_vehicle("paper"))
    d = not_separable(partial, ident, base_trade(partial, fit), None)
    assert d.status == "base_parameters" and d.top == ()
    assert "torsional stiffness at the motor 0.7" in d.reason and "cannot tell housing_mount" in d.reason
    assert d.details["not_separable"] == [{"effect_param": "housing_mount.stiffness_log2",
                                           "base_param": "base_stiffness.log2_scale", "correlation": -0.94}]
    assert [i["name"] for i in d.details["base_parameters"]] == ["stiffness"]


def test_an_effect_the_identified_base_cannot_stand_in_for_is_named_despite_a_trade_off() -> None:
    """A strong tyre slip on a car 10 % heavier than its file: in the joint fit the tyre's relaxation length trades
    off with the shaft stiffness, but the identified base alone explains little of the held-out residual and the
    tyre nearly all of it, so the held-out events tell them apart and the tyre is named."""
    res = diagnose_signals(_drive({"mass": 1.1}, {"tyre_slip": {"compliance_per_mn": 30.0, "relaxation_m": 0.5}}, 61),
                           paper(), DiagnosisOptions(seed=0, candidates=("tyre_slip", "torque_lag", "drag",
                                                                         "housing_mount")))
    d = res.decision
    assert d.status in ("explained", "partial") and d.top == ("tyre_slip",), d.reason
    assert res.identified_score is not None and d.best is not None
    assert res.identified_score.explained.value < 0.5 < d.best.explained.value
    trade = d.details["base_trade_off"]
    assert trade and all(abs(t["correlation"]) >= 0.9 and t["effect_param"].startswith("tyre_slip.") for t in trade)
    assert d.details["preferred_to_base"]["probability"] >= 0.9
    assert "held-out events prefer tyre_slip to the identified base alone" in d.reason


def test_a_data_sheet_error_says_which_effects_would_change_the_log_alike() -> None:
    """A mount 0.76x as stiff as the file's on a right data sheet reads as a 0.95x shaft stiffness (a soft mount
    lowers the shuffle mode like a soft shaft): the answer stays base_parameters, and it names the mount as what
    would explain the log to first order if the data sheet is known to be right; a torque lag, which changes the
    log otherwise, is not named."""
    res = diagnose_signals(_drive({}, {"housing_mount": {"stiffness_log2": -0.4, "damping_log2": 0.0}}, 81),
                           paper(), DiagnosisOptions(seed=0, candidates=("housing_mount", "torque_lag", "drag")))
    d = res.decision
    assert d.status == "base_parameters" and d.top == (), d.reason
    alike = {m["effect"]: m["linear_share"] for m in d.details["mimicked_by"]}
    assert set(alike) == {"housing_mount"} and 0.5 <= alike["housing_mount"] <= 1.0
    assert "housing_mount would remove" in d.reason and "rule that out before correcting it" in d.reason
    assert report_dict(res)["decision"]["mimicked_by"] == d.details["mimicked_by"]


def test_an_effect_the_identification_takes_in_part_is_named_on_a_correct_data_sheet() -> None:
    """A shaft that hardens under load, on a car whose data sheet is right: the identification reads it as a stiffer
    shaft (1.7x) that explains only part of the held-out gap. The candidates' screen on the file's vehicle puts the
    hardening first, it is refitted with the base parameters from the file's values, and it is named, with the
    base parameters back at the file's."""
    res = diagnose_signals(_drive({}, {"progressive_stiffness": {"halfshaft_rel": 2.0, "mount_rel": 0.0}}, 71),
                           paper(), DiagnosisOptions(seed=0, candidates=("progressive_stiffness", "housing_mount",
                                                                         "torque_lag", "drag")))
    d = res.decision
    assert d.status in ("explained", "partial") and d.top == ("progressive_stiffness",), d.reason
    assert res.identification_note.startswith("identification: torsional stiffness at the motor 1.")
    screened = next(line for line in res.fit_order if line.startswith("candidates on the file's vehicle"))
    assert screened.split(": ", 1)[1].startswith("progressive_stiffness ")
    assert any(line.startswith("progressive_stiffness + base parameters (jointly") for line in res.fit_order)
    # ... and held against the base alone refitted from that joint fit (rebase.base_alone), which it beats
    alone = next(line for line in res.fit_order if line.startswith("base parameters alone, from progressive_stiffness"))
    assert "progressive_stiffness preferred to the base alone" in alone, alone
    assert res.identified_score is not None and d.best is not None
    assert res.identified_score.explained.value < 0.75 < d.best.explained.value
    # refitted with the base parameters from both sides (rebase.joint_with_base), they come back to the file's, which
    # is right (from 1.7x stiffness identified alone). Where the refit ends on the ridge the hardening and the shaft
    # trade along moves with the last digits of the arithmetic (machine, library versions) and with the single fit the
    # greedy pairs leave: on one machine nothing is named; on another, stiffness 1.04x and mass 1.07x, each just past
    # its practical threshold; with the partner screen bounded as its fits are, stiffness 1.05x and mass 1.08x; with
    # numpy 2.4.6 and scipy 1.17.1, stiffness 1.11x and mass 1.08x (against 1.7x identified alone)
    named = {p["name"]: p["ratio"] for p in d.details.get("base_parameters") or []}
    assert all(abs(r - 1.0) < 0.15 for r in named.values()), named
    assert "base_trade_off" not in d.details


def test_an_effect_is_not_attributed_when_the_vehicle_cannot_be_identified_first() -> None:
    """3 calibration events: the diagnosis can still fit the candidates, but not identify the vehicle before them,
    so a torque lag that would explain the gap is reported as what it would attribute, not attributed; with one
    calibration event more the vehicle is identified first and the lag is named."""
    from tests.diagnosis.conftest import drive_signals
    opts = DiagnosisOptions(candidates=("torque_lag", "drag"), seed=1, max_pairs=0)
    few = diagnose_signals(drive_signals("torque_lag", (("tau_s", 0.02), ("delay_s", 0.0)), 31, 22.0), paper(), opts)
    assert len(few.split.calibration) == 3
    d = few.decision
    assert d.status == "insufficient_data" and d.top == ()
    assert d.details["would_attribute"] == ["torque_lag"] and d.details["identify_first"] is True
    assert "could not be identified first" in d.reason and "needs at least 4" in d.reason
    more = diagnose_signals(drive_signals("torque_lag", (("tau_s", 0.02), ("delay_s", 0.0)), 31, 26.0), paper(), opts)
    assert len(more.split.calibration) == 4 and more.identification is not None
    assert more.decision.status == "explained" and more.decision.top == ("torque_lag",)


@pytest.fixture(scope="module")
def tyre_on_file() -> dict[str, Any]:
    """A tyre's slip on a right data sheet, prepared as the diagnosis prepares it: events, split, the file's baseline,
    the identification (which reads the tyre as a softer shaft and a lighter car) and the tyre fitted alone."""
    from app.analysis.diagnosis.calibrate import Bounds, fit
    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
    from app.analysis.diagnosis.split import make_split
    from app.identify import FitOptions, identify_events
    from app.identify.logs import prepared_logs
    from sim.effects import get_effect
    from tests.diagnosis.conftest import drive_signals

    sig = drive_signals("tyre_slip", (("compliance_per_mn", 24.0), ("relaxation_m", 0.38)), 8, duration_s=40.0)
    events, noise, _ = prepared_logs([("log", sig)], DIAGNOSIS_EVENTS)
    split = make_split(events, 0)
    cal = split.calibration_events(events)
    bounds = Bounds.for_period(noise.period_s)
    base = fit(paper(), cal, split, (), bounds=bounds)
    ident = identify_events(events, noise, paper(), FitOptions(seed=0), split=split, baseline=base)
    single = fit(paper(), cal, split, (get_effect("tyre_slip"),), bounds=bounds, start=base)
    return {"events": events, "split": split, "cal": cal, "bounds": bounds, "ident": ident, "single": single}


def test_the_joint_refit_with_the_base_also_starts_from_the_file_side(tyre_on_file: dict[str, Any]) -> None:
    """A tyre's relaxation trades along a ridge with the shaft's stiffness: an effect fitted on the file's vehicle is
    itself a point of its joint model with the base parameters (the base at the file's values), so the joint refit
    starts from there as well as from the identified base, and is never worse on calibration events than the single
    fit it refines. On this drive the identification reads the tyre as a shaft at 0.56x the file's stiffness and a
    car at 0.64x its mass; refined from there alone, the joint fit ends worse than the tyre on the file's vehicle
    with the stiffness 6 % off, and from both sides it keeps the file's stiffness, which is the truth."""
    from app.analysis.diagnosis.rebase import joint_with_base

    t = tyre_on_file
    cal, split, bounds, ident, single = t["cal"], t["split"], t["bounds"], t["ident"], t["single"]
    assert ident.ratios  # base parameters were fitted (the drive's tyre shows as a softer shaft to a base-only fit)
    identified_side = joint_with_base(paper(), ident, cal, split, "tyre_slip", single, bounds, "multibody")
    both = joint_with_base(paper(), ident, cal, split, "tyre_slip", single, bounds, "multibody", single_on_file=True)
    assert identified_side is not None and both is not None
    assert both.chi2 <= min(single.chi2, identified_side.chi2) * (1.0 + 1e-9)
    stiffness = 2.0 ** both.values["base_stiffness"]["log2_scale"] if "base_stiffness" in both.values else 1.0
    assert stiffness == pytest.approx(1.0, abs=0.02)


def test_the_base_alone_is_refitted_from_an_effects_joint_fit(tyre_on_file: dict[str, Any]) -> None:
    """rebase.base_alone: the identification's base parameters refitted with the effect switched off, started at the
    joint fit's values. It fits the base effects only, in the identification's order; the tyre is real, so the base
    alone fits the calibration events worse than the tyre with the base."""
    from app.analysis.diagnosis.rebase import base_alone, joint_with_base
    from app.identify.base import BASE_EFFECTS

    t = tyre_on_file
    cal, split, bounds, ident = t["cal"], t["split"], t["bounds"], t["ident"]
    joint = joint_with_base(paper(), ident, cal, split, "tyre_slip", t["single"], bounds, "multibody",
                            single_on_file=True)
    assert joint is not None
    alone = base_alone(paper(), ident, joint, cal, split, bounds, "multibody")
    assert list(alone.effects) == [BASE_EFFECTS[k].id for k in ident.ratios]
    assert "tyre_slip" not in alone.values and set(alone.values) == set(alone.effects)
    assert alone.chi2 > joint.chi2


def test_an_effect_no_better_than_the_base_alone_is_not_attributed(tyre_on_file: dict[str, Any]) -> None:
    """rebase.effect_not_needed: an effect that held-out events do not prefer to the base alone gives
    ``base_parameters`` with the refitted base's named parameters, the two figures and the bootstrap's verdict in the
    reason; where that base names nothing either, ``none_of_candidates``."""
    from dataclasses import replace

    from app.analysis.diagnosis.decide import Decision, DecisionRules, bootstrap_draws, gap_ratio, score_candidate
    from app.analysis.diagnosis.rebase import effect_not_needed
    from app.analysis.diagnosis.score import Interval

    ident = tyre_on_file["ident"]
    assert ident.named  # the identification reads the tyre as a softer shaft and a lighter car
    rules = DecisionRules()
    n = np.full(8, 100.0)
    base = np.full(8, 900.0)
    draws = bootstrap_draws(8, rules, 0)
    with_effect = score_candidate("tyre_slip", ("tyre_slip",), base, np.full(8, 200.0), n, draws, rules, None)
    alone = score_candidate("base_parameters", (), base, np.full(8, 202.0), n, draws, rules, None)
    decision = Decision("partial", top=("tyre_slip",), reason="tyre_slip: ...", best=with_effect)
    share = Interval(0.01, -0.05, 0.07)
    out = effect_not_needed(decision, ident, with_effect, alone, n, gap_ratio(base, n, draws, 0.9), 0.4, 0.02, share,
                            rules)
    assert out.status == "base_parameters" and out.top == () and out.best is alone
    assert {i["name"] for i in out.details["base_parameters"]} == set(ident.named)
    assert out.details["effect_not_needed"] == {"effect": "tyre_slip", "probability": 0.4, "separation": 0.02,
                                                "share_of_base_remainder": {"value": 0.01, "lo": -0.05, "hi": 0.07}}
    assert "the vehicle file is off" in out.reason and "leaves 2.00x" in out.reason and "leave 2.02x" in out.reason
    assert "probability 0.40" in out.reason and "removes 1 % [-5, 7] of what the base alone leaves" in out.reason
    quiet = replace(ident, params={k: replace(p, named=False) for k, p in ident.params.items()})
    none = effect_not_needed(decision, quiet, with_effect, alone, n, None, 0.4, 0.02, share, rules)
    assert none.status == "none_of_candidates" and none.top == () and "base_parameters" not in none.details
