"""The grey-box identification on prepared events: values, intervals, identifiability, bad input."""

from __future__ import annotations

import numpy as np
import pytest

import app.identify.fit as fitmod
from app.analysis.diagnosis.calibrate import Bounds, FitResult, chi2_at, linear_reach
from app.analysis.diagnosis.calibrate import fit as calfit
from app.errors import InsufficientDataError, NotIdentifiableError
from app.identify import FitOptions, identify_events, physical, with_base
from app.identify.base import BASE_EFFECTS, effective_stiffness, first_mode, lash_mrad
from app.identify.fit import (
    LASH_SAME_BASIN,
    LASH_STARTS,
    PIN_RECHECK,
    REACH_SKIP,
    all_events_split,
    gain_onto_mass,
    interval_reaches,
    lash_moved,
    off_the_gain_bound,
)
from app.signals import Signal, SignalSet
from sim import load_vehicle
from sim.effects import apply_effects
from tests.identify.drives import OFF, drive_signals, prepared
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals


@pytest.fixture(scope="module")
def off_result():  # type: ignore[no-untyped-def]
    events, noise = prepared(drive_signals(OFF, seed=5))
    return identify_events(events, noise, load_vehicle("paper"))


def test_effective_stiffness_is_the_series_sum_referred_to_the_rotor() -> None:
    v = load_vehicle("paper")
    red, hs = v.reducer, v.halfshaft
    assert red is not None and hs is not None
    r1, r = red.ratio1, red.ratio
    compliance = (1 / red.spline_stiffness + r1 ** 2 / red.mesh1_stiffness + r ** 2 / red.mesh2_stiffness
                  + r ** 2 / red.diff_stiffness + r ** 2 / (hs.count * hs.stiffness))
    assert effective_stiffness(v) == pytest.approx(1 / compliance, rel=1e-9)
    # every stiffness x 0.6: the effective stiffness x 0.6, the mode near x sqrt(0.6) (the rotor side dominates;
    # the housing on its mounts and the damping move it a little)
    soft = with_base(v, {"stiffness": 0.6})
    assert effective_stiffness(soft) == pytest.approx(0.6 / compliance, rel=1e-9)
    assert first_mode(soft)[0] / first_mode(v)[0] == pytest.approx(np.sqrt(0.6), rel=0.05)
    assert lash_mrad(with_base(v, {"lash": 1.3})) == pytest.approx(1.3 * lash_mrad(v), rel=1e-9)


def test_every_base_parameter_recovered_with_an_interval_that_holds_it(off_result) -> None:  # type: ignore[no-untyped-def]
    truth = physical(with_base(load_vehicle("paper"), OFF))
    for name in ("stiffness", "damping", "mass", "lash"):
        p = off_result.params[name]
        assert p.identified and not p.at_bound and p.named, (name, p)
        assert p.value == pytest.approx(truth.value(name), rel=0.03), name
        assert p.lo <= truth.value(name) <= p.hi, (name, p)
    assert off_result.params["torque_gain"].value == pytest.approx(1.0, abs=0.02)
    assert sorted(off_result.named) == ["damping", "lash", "mass", "stiffness"]
    assert off_result.chi2_after < 0.1 * off_result.chi2_before
    # the model-free mode sees the truth's first mode, not the file's
    assert off_result.modal is not None
    assert off_result.modal.freq_hz == pytest.approx(truth.freq_hz, rel=0.05)


def test_each_interval_is_its_statistics_and_its_model_form_in_quadrature(off_result) -> None:  # type: ignore[no-untyped-def]
    from app.identify.fit import model_form

    parts = off_result.interval_parts
    assert sorted(parts) == ["damping", "lash", "mass", "stiffness"]
    # the identified car's move from its file: the four figures' log ratios in quadrature, the same for each
    logs = [np.log(off_result.params[q].value / off_result.params[q].nominal) for q in parts]
    assert all(part.move == pytest.approx(float(np.sqrt(np.sum(np.square(logs))))) for part in parts.values())
    assert parts["stiffness"].move > 0.2  # the OFF file is far off
    for name, part in parts.items():
        p = off_result.params[name]
        form = np.log1p(model_form(name, part.scale, move=part.move) * part.misfit)
        assert np.log(p.hi / p.value) == pytest.approx(np.hypot(part.stat, form), rel=1e-12), name
        assert np.log(p.value / p.lo) == pytest.approx(np.hypot(part.stat, form), rel=1e-12), name
        assert part.scale == 1.0 and part.misfit >= 1.0 and part.stat >= 0.0  # 1 kHz: ten samples a period and more


def test_a_correct_file_names_nothing() -> None:
    events, noise = prepared(drive_signals({}, seed=6, duration_s=30.0))
    res = identify_events(events, noise, load_vehicle("paper"))
    assert res.named == []
    for name in ("stiffness", "mass", "lash"):
        p = res.params[name]
        assert p.value == pytest.approx(p.nominal, rel=0.04), name


def test_a_subset_of_parameters_keeps_the_rest_at_the_file() -> None:
    events, noise = prepared(drive_signals({"mass": 1.2}, seed=7, duration_s=30.0))
    res = identify_events(events, noise, load_vehicle("paper"), FitOptions(params=("mass",)))
    assert res.named == ["mass"]
    assert res.params["mass"].value == pytest.approx(1.2 * 1750.0, rel=0.03)
    assert not res.params["stiffness"].identified and res.params["stiffness"].note == "not fitted"
    assert res.params["stiffness"].value == res.params["stiffness"].nominal


def test_too_few_events_is_insufficient_data() -> None:
    events, noise = prepared(drive_signals({}, seed=8, duration_s=30.0))
    with pytest.raises(InsufficientDataError) as err:
        identify_events(events[:3], noise, load_vehicle("paper"))
    assert err.value.code == "insufficient_data" and "at least 4" in str(err.value)


def test_a_speed_that_does_not_respond_to_the_torque_is_not_identifiable() -> None:
    sig = drive_signals({}, seed=9, duration_s=30.0)
    sp = sig["motor_speed_rpm"]
    rng = np.random.default_rng(0)
    flat = SignalSet()
    flat.add(sig["motor_torque_nm"])
    flat.add(Signal.from_samples("motor_speed_rpm", sp.t, 3000.0 + rng.normal(0, 0.5, sp.t.size), "rpm"))
    events, noise = prepared(flat)
    with pytest.raises(NotIdentifiableError) as err:
        identify_events(events, noise, load_vehicle("paper"))
    assert err.value.code == "not_identifiable" and "does not respond to the torque" in str(err.value)


def test_a_vehicle_without_the_field_is_not_identifiable() -> None:
    v = load_vehicle("paper")
    no_lash = v.with_changes({f"gaps.{g}": 0.0 for g in v.gap_names})
    events, noise = prepared(drive_signals({}, seed=10, duration_s=30.0))
    with pytest.raises(NotIdentifiableError) as err:
        identify_events(events, noise, no_lash, FitOptions(params=("lash",)))
    assert "nothing identifiable" in str(err.value)
    with pytest.raises(NotIdentifiableError, match="unknown base parameters"):
        identify_events(events, noise, v, FitOptions(params=("stiffness", "colour")))


def test_bursty_50_hz_sampling_still_identifies_the_stiffness() -> None:
    sampling = CanSampling(period_s=0.02, jitter_s=0.001, drop_fraction=0.03)
    events, noise = prepared(drive_signals({"stiffness": 0.7}, seed=11, duration_s=40.0, sampling=sampling))
    res = identify_events(events, noise, load_vehicle("paper"))
    p = res.params["stiffness"]
    assert p.value / p.nominal == pytest.approx(0.7, rel=0.05)
    assert "stiffness" in res.named


def test_stiffness_and_damping_come_from_a_clear_measured_mode() -> None:
    """A clean 100 Hz drive: the model-free mode sets stiffness and damping (the fit log says so) and the rest is
    fitted on top; the result holds the truth."""
    events, noise = prepared(drive_signals({"stiffness": 0.8, "damping": 1.5}, seed=12, duration_s=40.0))
    res = identify_events(events, noise, load_vehicle("paper"))
    assert any(line.startswith("stiffness and damping from the model-free first mode") for line in res.fit_log)
    assert res.params["stiffness"].ratio == pytest.approx(0.8, rel=0.03)
    assert res.params["damping"].ratio == pytest.approx(1.5, rel=0.1)
    assert {"stiffness", "damping"} <= set(res.named) and "mass" not in res.named


def test_a_speed_channel_too_slow_for_the_mode_leaves_stiffness_and_damping_unidentified() -> None:
    """20 Hz sampling of the chain-drive car, whose file puts the first mode near 16 Hz: what the log shows of the
    mode is folded; stiffness and damping stay at the file's values, said so, and mass and lash are still fitted."""
    sampling = CanSampling(period_s=0.05, jitter_s=0.001, drop_fraction=0.0)
    events, noise = prepared(drive_signals({"mass": 1.2}, seed=13, duration_s=60.0, vehicle="chain_drive",
                                           sampling=sampling))
    res = identify_events(events, noise, load_vehicle("chain_drive"))
    for name in ("stiffness", "damping"):
        p = res.params[name]
        assert not p.identified and p.note == "the speed channel is too slow for the first mode", p
    assert res.params["mass"].identified
    assert any("not resolved by a 20 Hz speed channel" in line for line in res.fit_log)
    # the chain's lash is crossed in a few tens of ms, under two samples at 20 Hz: held at the file's value, said so
    lash = res.params["lash"]
    assert not lash.identified and lash.ratio == 1.0
    assert "free traverse lasts" in lash.note and "20 Hz speed channel" in lash.note, lash.note


def test_the_model_form_floor_widens_below_ten_samples_per_mode_period() -> None:
    from app.identify.fit import MODE_SAMPLES, model_form_scale

    assert model_form_scale(7.7, 0.01) == 1.0 and model_form_scale(7.7, 0.001) == 1.0  # the paper car, 100 Hz, 1 kHz
    assert model_form_scale(5.5, 0.04) == pytest.approx(5.5 * 0.04 * MODE_SAMPLES)  # 25 Hz: 2.2x
    assert model_form_scale(float("nan"), 0.04) == 1.0 and model_form_scale(5.5, 0.0) == 1.0



def test_the_model_form_floor_has_its_calibrated_level_and_slope() -> None:
    from app.identify.fit import MODEL_FORM, model_form, model_form_scale

    # at ten or more samples per mode period: the level alone (the paper car at 100 Hz and 1 kHz)
    assert {q: model_form(q, model_form_scale(7.7, 0.01)) for q in MODEL_FORM} == {
        "stiffness": 0.0036, "damping": 0.005, "mass": 0.0064, "lash": 0.0072}
    # the low-mode chain car at 25 Hz (2.2x the scale): each parameter's slope on top, the mass' steepest
    scale = model_form_scale(5.5, 0.04)
    assert model_form("stiffness", scale) == pytest.approx(0.0036 + 0.015 * 1.2)
    assert model_form("damping", scale) == pytest.approx(0.005 + 0.04 * 1.2)
    assert model_form("mass", scale) == pytest.approx(0.0064 + 0.06 * 1.2)
    assert model_form("lash", scale) == pytest.approx(0.0072 + 0.02 * 1.2)
    with pytest.raises(KeyError):
        model_form("torque_gain", 1.0)


def test_the_model_form_floor_grows_with_the_identified_cars_move_from_its_file() -> None:
    from app.identify.fit import MOVE_FORM, model_form, move_from_file

    paper = load_vehicle("paper")
    nominal = physical(paper)
    assert move_from_file(nominal, nominal, ["stiffness", "mass", "lash"]) == 0.0
    moved = physical(with_base(paper, {"stiffness": 1.3, "mass": 0.9}))
    # the figures' log ratios in quadrature, over the parameters named only
    logs = [np.log(moved.value(q) / nominal.value(q)) for q in ("stiffness", "mass")]
    move = move_from_file(nominal, moved, ["stiffness", "mass"])
    assert move == pytest.approx(np.sqrt(np.sum(np.square(logs)))) and move > 0.25
    assert move_from_file(nominal, moved, ["lash"]) == pytest.approx(0.0, abs=1e-12)
    # each parameter's floor: its level plus the same amount per unit of move
    for q in ("stiffness", "damping", "mass", "lash"):
        assert model_form(q, 1.0, move=move) == pytest.approx(model_form(q, 1.0) + MOVE_FORM * move)
    assert model_form("stiffness", 1.0, move=0.5, per_move=0.0) == model_form("stiffness", 1.0)


def test_staged_identification_stops_once_two_stages_agree() -> None:
    """Stages of 8, 16, ... of a 2-minute drive's events in the stratified order: the design stops when the new
    stage's intervals hold the previous stage's values and the same parameters are named, and holds the truth."""
    from app.identify import identify_staged
    events, noise = prepared(drive_signals(OFF, seed=5, duration_s=120.0))
    said: list[str] = []
    res = identify_staged(events, noise, load_vehicle("paper"), progress=lambda f, m: said.append(m), first=8)
    head = res.fit_log[0]
    assert head.startswith("sequential design (events: named): 8: "), head
    assert "stable, stopped" in head and res.n_events < len(events), head
    assert sorted(res.named) == ["damping", "lash", "mass", "stiffness"]
    truth = physical(with_base(load_vehicle("paper"), OFF))
    for name in ("stiffness", "mass", "lash"):
        # within 1.5 % of the truth, and within twice its 90 % half-width (one drive: a 90 % interval itself misses
        # one time in ten; calibrated on the generator's drives, docs/identify.md; this drive's stiffness, 0.47 % low
        # at +-0.46 %, is one)
        p = res.params[name]
        miss = abs(np.log(p.value / truth.value(name)))
        assert miss <= 0.015 and miss <= 2.0 * np.log(p.hi / p.value), (name, p)
    assert any(m.startswith("stage 2 (16 events)") for m in said)
    # a drive no longer than a first stage is one identification of all its events
    assert identify_staged(events[:12], noise, load_vehicle("paper"), first=12).n_events == 12


def _tyre_drive(seed: int):  # type: ignore[no-untyped-def]
    """A paper car 10 % heavier than its file, whose tyres slip (an effect no base parameter is)."""
    paper = load_vehicle("paper")
    truth = apply_effects(with_base(paper, {"mass": 1.1}), {"tyre_slip": {"compliance_per_mn": 25.0,
                                                                          "relaxation_m": 0.3}})
    rng = np.random.default_rng(seed)
    drive = make_drive(paper, rng, DriveSpec(duration_s=40.0))
    return prepared(to_signals(measure(drive, run_truth(truth, drive), CanSampling(period_s=0.01), rng)))


def _counted(monkeypatch: pytest.MonkeyPatch) -> list[int]:
    """Simulator passes of every fit and first-order reach the identification runs, as they run."""
    passes: list[int] = []
    fit, reach = fitmod.fit, fitmod.linear_reach

    def counted_fit(*a, **kw):  # type: ignore[no-untyped-def]
        res = fit(*a, **kw)
        passes.append(res.nfev)
        return res

    def counted_reach(*a, **kw):  # type: ignore[no-untyped-def]
        res = reach(*a, **kw)
        passes.append(0 if res is None else res.nfev)
        return res

    monkeypatch.setattr(fitmod, "fit", counted_fit)
    monkeypatch.setattr(fitmod, "linear_reach", counted_reach)
    return passes


def test_the_grey_box_is_not_refitted_where_its_first_step_cannot_reach_the_noise_floor(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """The mode's stiffness and damping leave a tyre's slip, many times the noise floor: the grey box fitting them
    too would, to first order, leave nearly as much, so it is not fitted; the answer is the one its fit gave."""
    events, noise = _tyre_drive(7)
    paper = load_vehicle("paper")
    passes = _counted(monkeypatch)
    quick = identify_events(events, noise, paper, FitOptions(seed=7))
    quick_passes = sum(passes)
    skipped = [line for line in quick.fit_log if "to first order" in line]
    assert len(skipped) == 1 and "the mode's values kept" in skipped[0]
    left = float(skipped[0].split("would leave ")[1].split(" ")[0])
    assert left > REACH_SKIP * PIN_RECHECK

    passes.clear()
    monkeypatch.setattr(fitmod, "REACH_SKIP", float("inf"))  # the grey box fitted every time, as before
    full = identify_events(events, noise, paper, FitOptions(seed=7))
    assert any(line.startswith("the grey box fitting stiffness and damping too leaves") for line in full.fit_log)
    assert quick.ratios == full.ratios and quick.named == full.named
    assert quick.chi2_after == full.chi2_after
    assert quick_passes < 0.7 * sum(passes)


def test_the_first_step_of_a_refit_promises_what_a_near_linear_parameter_gives() -> None:
    """A car 15 % heavier than its file: from the file's values, the mass's first Gauss-Newton step (with the
    nuisance) promises about what its fit removes, at one pass at the start and one per parameter."""
    paper = load_vehicle("paper")
    events, noise = prepared(drive_signals({"mass": 1.15}, seed=9))
    split = all_events_split(events)
    bounds = Bounds.for_period(noise.period_s)
    base = calfit(paper, events, split, (), bounds=bounds, seed=9)
    mass = BASE_EFFECTS["mass"]
    reach = linear_reach(paper, events, split, (mass,), base, bounds=bounds)
    assert reach is not None and reach.nfev == 4  # the start, torque gain, road load, mass
    assert reach.chi2_at == pytest.approx(base.chi2, rel=1e-9) and reach.n == base.n
    start = FitResult((), base.nuisance, {mass.id: {"scale": 1.0}}, 0.0, 0, 0)
    fitted = calfit(paper, events, split, (mass,), bounds=bounds, start=start, screen=False, seed=9)
    assert fitted.values[mass.id]["scale"] == pytest.approx(1.15, rel=0.03)
    assert fitted.chi2 < reach.chi2 < 0.1 * reach.chi2_at


def test_the_pins_uncertainty_is_carried_into_what_is_fitted_on_them(monkeypatch: pytest.MonkeyPatch) -> None:
    """Stiffness and damping set from the model-free mode carry an interval of their own; mass and lash are fitted on
    them. The first-order slopes of the fitted values on each pin predict where a refit with that pin moved lands,
    and the fitted parameters' intervals widen by what the pins' uncertainty moves them (the pinned ones do not)."""
    events, noise = prepared(drive_signals({"stiffness": 0.8, "damping": 1.5, "lash": 1.2}, seed=12,
                                           duration_s=40.0, sampling=CanSampling(period_s=0.001)))
    vehicle = load_vehicle("paper")
    seen: dict[str, object] = {}
    spread = fitmod.pin_spread

    def keep(*args: object) -> object:
        seen["args"] = args
        return spread(*args)  # type: ignore[arg-type]

    monkeypatch.setattr(fitmod, "pin_spread", keep)
    res = identify_events(events, noise, vehicle)
    names, pins, joint = seen["args"][1:4]  # type: ignore[index]
    assert sorted(pins) == ["damping", "stiffness"] and "lash" in names and "mass" in names
    slopes = fitmod.pin_slopes(*seen["args"][:7])  # type: ignore[index, arg-type]
    assert slopes is not None and slopes.shape == (joint.jac.shape[1], 2)
    # the damping pin moved by 1 % (the pins still come within the noise floor, so they are kept): where mass and
    # lash go, against the slopes' prediction
    monkeypatch.setattr(fitmod, "pin_spread", spread)
    pinned = fitmod.mode_pins

    def moved(*args, **kw):  # type: ignore[no-untyped-def]
        p = dict(pinned(*args, **kw))
        p["damping"] = (p["damping"][0] * 1.01, p["damping"][1])
        return p

    monkeypatch.setattr(fitmod, "mode_pins", moved)
    again = identify_events(events, noise, vehicle)
    assert not any("fitted by the grey box instead" in m for m in again.fit_log)  # the moved pins were kept
    col = list(pins).index("damping")
    for q in ("mass", "lash"):
        k = fitmod.N_NUISANCE + list(names).index(q)
        spec = BASE_EFFECTS[q].params[0]
        predicted = slopes[k, col] * (spec.hi - spec.lo) / res.params[q].ratio * np.log(1.01)
        actual = np.log(again.params[q].ratio / res.params[q].ratio)
        assert abs(actual - predicted) <= 0.3 * abs(actual) + 0.0005, (q, actual, predicted)
    # the intervals: wider for what was fitted on the pins than without their spread, the same for the pins
    monkeypatch.setattr(fitmod, "mode_pins", pinned)
    monkeypatch.setattr(fitmod, "pin_spread", lambda *a: None)
    bare = identify_events(events, noise, vehicle)
    for q in ("mass", "lash"):
        assert res.params[q].value == pytest.approx(bare.params[q].value, rel=1e-9)
        assert res.interval_parts[q].stat > bare.interval_parts[q].stat
    for q in ("stiffness", "damping"):
        assert res.params[q].lo == pytest.approx(bare.params[q].lo, rel=1e-12)


def test_an_interval_past_the_priors_bound_is_held_by_the_prior() -> None:
    # the lash is fitted as a scale, 0.3-2.5; the stiffness as log2 of one, -3.3..1.6 (0.102x-3.03x)
    assert interval_reaches("lash", 0.29, 0.325 ** 2 / 0.29) == "0.3x the file's"
    assert interval_reaches("lash", 0.31, 0.325 ** 2 / 0.31) == ""
    assert interval_reaches("lash", 2.2 ** 2 / 2.6, 2.6) == "2.5x the file's"
    assert interval_reaches("stiffness", 2.0 ** 1.4, 2.0 ** 1.6) == "3.03x the file's"
    assert interval_reaches("stiffness", 2.0 ** 0.9, 2.0 ** 1.1) == ""
    assert interval_reaches("stiffness", 2.0 ** -3.4, 2.0 ** -3.0) == "0.102x the file's"


def test_a_fit_held_by_the_gain_bound_is_refined_again_along_the_rigid_body_ridge() -> None:
    """A paper car 15 % heavier than its file with a 13 ms torque lag. The rigid body pins the torque gain per unit
    mass, not either: a refinement stopped with the gain on its 0.85 bound and the mass at 0.99x (the valley a lag on
    a heavier car fell into on the independent generator's drive) is refined again from the gain at 1 and the mass at
    0.99 / 0.85, and reaches the truth; a fit inside the gain's bounds is left as it is."""
    from app.analysis.diagnosis.forward import Nuisance
    from sim.effects import get_effect

    paper = load_vehicle("paper")
    truth = apply_effects(with_base(paper, {"mass": 1.15}), {"torque_lag": {"tau_s": 0.013, "delay_s": 0.0}})
    rng = np.random.default_rng(3)
    drive = make_drive(paper, rng, DriveSpec(duration_s=30.0))
    events, noise = prepared(to_signals(measure(drive, run_truth(truth, drive), CanSampling(period_s=0.01), rng)))
    split = all_events_split(events)
    effects = (BASE_EFFECTS["mass"], get_effect("torque_lag"))

    def refine(start: FitResult) -> FitResult:
        return calfit(paper, events, split, effects, bounds=Bounds.for_period(noise.period_s), start=start,
                      screen=False, passes_per_param=8)

    valley = {"base_mass": {"scale": 0.99}, "torque_lag": {"tau_s": 0.005, "delay_s": 0.0}}
    stuck = calfit(paper, events, split, effects, bounds=Bounds.for_period(noise.period_s),
                   start=FitResult((), Nuisance(gain=0.851), valley, 0.0, 0, 0), screen=False, max_passes=1)
    assert "nuisance.gain" in stuck.at_bound
    moved = gain_onto_mass(stuck)
    assert moved.nuisance.gain == 1.0 and moved.nuisance.offset_s == stuck.nuisance.offset_s
    assert moved.values["base_mass"]["scale"] == pytest.approx(0.99 / 0.851)
    assert moved.values["torque_lag"] == stuck.values["torque_lag"]

    out = off_the_gain_bound(stuck, refine)
    assert out.chi2 < 0.2 * stuck.chi2
    assert out.nuisance.gain == pytest.approx(1.0, abs=0.02)
    assert out.values["base_mass"]["scale"] == pytest.approx(1.15, rel=0.02)
    assert out.values["torque_lag"]["tau_s"] == pytest.approx(0.013, abs=0.0015)
    assert "nuisance.gain" not in out.at_bound

    def not_called(start: FitResult) -> FitResult:
        raise AssertionError("a fit inside the gain's bounds is not refined again")

    assert off_the_gain_bound(out, not_called) is out
    # the mass moved onto a bound of its own prior is clipped there (a start, not a fit)
    heavy = gain_onto_mass(FitResult((), Nuisance(gain=0.85), {"base_mass": {"scale": 1.6}}, 0.0, 0, 0))
    assert heavy.values["base_mass"]["scale"] == BASE_EFFECTS["mass"].params[0].hi


def test_the_lash_screen_tells_a_point_in_the_files_basin_from_the_truths() -> None:
    """A paper car with 0.7x its file's lash and 0.94x its mass. ``chi2_at`` gives a fit's own chi2 back from one
    pass; the fit's point with the lash moved to each further start (and each moved along the gain-mass ridge) leaves
    more than the fit, which is in the truth's basin (the start at 0.7x, the fit's own basin, is not screened); a point
    near the file's lash leaves more than its own point moved to 0.7x: the screen that sends ``_joint`` to refine
    again from the lash's other starts."""
    from app.analysis.diagnosis.forward import Nuisance

    paper = load_vehicle("paper")
    truth = with_base(paper, {"lash": 0.7, "mass": 0.94})
    rng = np.random.default_rng(3)
    drive = make_drive(paper, rng, DriveSpec(duration_s=30.0))
    events, noise = prepared(to_signals(measure(drive, run_truth(truth, drive), CanSampling(period_s=0.01), rng)))
    split = all_events_split(events)
    effects = (BASE_EFFECTS["mass"], BASE_EFFECTS["lash"])
    bounds = Bounds.for_period(noise.period_s)
    good = calfit(paper, events, split, effects, bounds=bounds, screen=False,
                  start=FitResult((), Nuisance(), {"base_mass": {"scale": 1.0}, "base_lash": {"scale": 1.0}}, 0, 0, 0))
    assert good.values["base_lash"]["scale"] == pytest.approx(0.7, rel=0.03)
    assert chi2_at(paper, events, split, effects, [good], bounds=bounds) == [pytest.approx(good.chi2, rel=1e-9)]

    moved = lash_moved(good)  # the start at 0.7x is the fit's own basin, left out
    far = [r for r in LASH_STARTS if abs(r / 0.7 - 1.0) > LASH_SAME_BASIN]
    assert far and len(far) < len(LASH_STARTS)
    assert [p.values["base_lash"]["scale"] for p in moved] == [*far, *far]
    assert all(p.values["base_mass"] == good.values["base_mass"] for p in moved[:len(far)])
    assert all(p.nuisance.gain == 1.0 for p in moved[len(far):])
    assert min(chi2_at(paper, events, split, effects, moved, bounds=bounds)) > good.chi2

    near_file = FitResult((), good.nuisance, {"base_mass": {"scale": 1.0}, "base_lash": {"scale": 1.02}}, 0, 0, 0)
    own, *screen = chi2_at(paper, events, split, effects, [near_file, *lash_moved(near_file)], bounds=bounds)
    assert min(screen) < 0.8 * own
    no_mass = lash_moved(FitResult((), good.nuisance, {"base_lash": {"scale": 1.0}}, 0, 0, 0))
    assert len(no_mass) == len(LASH_STARTS)
