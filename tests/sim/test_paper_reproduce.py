"""The paper's rows on its own quantities, both clearance readings, the fitted preset and its fit."""

from __future__ import annotations

import math
from importlib import resources

import numpy as np
import pytest

from sim import ParameterError, load_vehicle, load_vehicle_text
from sim.paper import (
    PAPER_SENSITIVITY,
    TipIn,
    load_tip_in,
    paper_cases,
    paper_rows,
    reading_errors,
    reproduce,
    sensitivities,
    tip_in_torque,
)
from sim.paper_fit import S_WEIGHT, FitResult, Param, apply, default_params, fitted_toml, residuals

PAPER = load_vehicle("paper")


@pytest.fixture(scope="module")
def paper_cases_default() -> dict:  # type: ignore[type-arg]
    return paper_cases(PAPER)


def test_rows_are_the_papers_quantities(paper_cases_default) -> None:  # type: ignore[no-untyped-def]
    """One row per paper figure; fluctuations, gap removals and S_i all on the peak-to-valley fluctuation."""
    cases = paper_cases_default
    rows = paper_rows(PAPER, cases)
    by = {r.quantity: r for r in rows}
    assert len(by) == len(rows) == 22
    assert all(r.ok is not None and r.target for r in rows)  # every row is a target, none only "reported"
    nom = cases["nominal"]
    assert by["fluctuation peak-valley, nominal gaps (rpm)"].ours == pytest.approx(nom.fluct_rpm)
    assert by["gaps 4+5 eliminated: peak-valley / nominal (%)"].ours == pytest.approx(
        100 * cases["gaps45"].fluct_rpm / nom.fluct_rpm)
    assert by["gaps 4+5 eliminated: peak-valley / nominal (%)"].paper == 18.0
    # the old preset and ramp: times met, amplitudes not (the numbers)
    assert by["unloaded time, nominal gaps (ms)"].ok
    assert by["fluctuation peak-valley, nominal gaps (rpm)"].ours == pytest.approx(401, abs=5)
    assert not by["fluctuation peak-valley, nominal gaps (rpm)"].ok
    assert by["gaps 4+5 eliminated: peak-valley / nominal (%)"].ours == pytest.approx(47, abs=2)
    # S5 = 100 by definition is not a row (it cannot fail)
    assert not any(q.startswith("S5") for q in by)


def test_clearance_readings(paper_cases_default) -> None:  # type: ignore[no-untyped-def]
    """Arc-minutes: S1:S2:S3 follow the motor-angle multipliers 1 : 2.93 : 11.26, as the paper's
    0.9 : 3 : 11 do; mm of arc cannot (the motor spline's small radius puts S1 above S2)."""
    cases = paper_cases_default
    am = sensitivities(PAPER, cases, per="arcmin", quantity="fluctuation")
    mult = np.array([PAPER.gap_speed_ratio(g) for g in PAPER.gap_names])
    assert mult[:3] == pytest.approx([1.0, 79 / 27, 79 / 27 * 77 / 20])
    assert am[:3] / am[2] == pytest.approx(mult[:3] / mult[2], rel=0.2)
    paper = np.array(PAPER_SENSITIVITY)
    assert paper[:3] / paper[2] == pytest.approx(mult[:3] / mult[2], rel=0.15)
    mm = sensitivities(PAPER, cases, per="mm", quantity="fluctuation")
    assert mm[0] > mm[1]  # against the paper's ranking
    assert np.allclose(mm, am * np.array(PAPER.gap_radii_mm)[-1] / np.array(PAPER.gap_radii_mm))
    assert sensitivities(PAPER, cases, per="rad", quantity="fluctuation") == pytest.approx(am)
    err = reading_errors(PAPER, cases)
    assert set(err) == {"arcmin", "mm"} and all(e > 0 for e in err.values())
    prop = reading_errors(PAPER, cases, 2, 2)  # S1 : S2 against S3: the arc-minute reading is far closer
    assert prop["arcmin"] < 0.1 < 0.3 < prop["mm"]
    with pytest.raises(ParameterError, match="per"):
        sensitivities(PAPER, cases, per="inch")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="quantity"):
        sensitivities(PAPER, cases, quantity="rms")  # type: ignore[arg-type]


def test_flexibility_does_not_lift_s4_s5_above_s3() -> None:
    """Gaps 3, 4, 5 all sit at wheel speed: per arc-minute the model gives S3 ~ S4 ~ S5 with or without
    the housing and with a rigid or a 6-segment half-shaft, so neither explains the paper's 11 : 36 : 100."""
    for change in ({}, {"housing.enabled": False}, {"halfshaft.segments": 1}, {"halfshaft.segments": 6}):
        v = PAPER.with_changes(change)
        s = sensitivities(v, paper_cases(v, twin=False), per="arcmin", quantity="fluctuation")
        assert s[2] == pytest.approx(100.0, rel=0.1) and s[3] == pytest.approx(100.0, rel=0.1), change


def test_tip_in_profile_and_file_table(tmp_path) -> None:  # type: ignore[no-untyped-def]
    t, q = tip_in_torque(profile=TipIn(-40.0, 200.0, 0.2, 0.1), duration_s=0.5)
    assert q[0] == -40.0 and q[-1] == 200.0
    assert np.interp(0.2, t, q) == pytest.approx(80.0)
    assert tip_in_torque()[1][20] == pytest.approx(-50 + 200 * 0.1 / 0.135)  # the default ramp is unchanged
    with pytest.raises(ParameterError, match="tip_in"):
        TipIn(50.0, 150.0)
    with pytest.raises(ParameterError, match="ramp_s"):
        TipIn(ramp_s=0.0)
    text = (tmp_path / "v.toml")
    base = (resources.files("sim") / "presets" / "paper.toml").read_text(encoding="utf-8")
    text.write_text(base + "\n[tip_in]\nstart_nm = -30.0\nend_nm = 120.0\nramp_s = 0.3\n")
    assert load_tip_in(str(text)) == TipIn(-30.0, 120.0, 0.3, 0.1)
    assert load_vehicle(text) == PAPER  # the vehicle loader skips [tip_in]
    assert load_tip_in("paper") is None
    text.write_text(base + "\n[tip_in]\nstart_nm = -30.0\nslope = 3\n")
    with pytest.raises(ParameterError, match=r"tip_in\.slope"):
        load_tip_in(str(text))
    assert load_vehicle_text(base + "\n[tip_in]\nstart_nm = -30.0\n").name == "paper"


def test_fit_residuals_are_the_rows_quantities(paper_cases_default) -> None:  # type: ignore[no-untyped-def]
    """The fit's cost is built from the rows' own quantities: no quantity is swapped to pass."""
    r = residuals(PAPER, TipIn())
    rows = {x.quantity: x for x in paper_rows(PAPER, paper_cases_default)}
    fl = rows["fluctuation peak-valley, nominal gaps (rpm)"].ours
    assert r["fluct_nominal"] == pytest.approx(math.log(fl / 231.0) / math.log(1.15), rel=1e-9)
    g45 = rows["gaps 4+5 eliminated: peak-valley / nominal (%)"].ours
    assert r["gaps45"] == pytest.approx((g45 - 18.0) / 5.0, rel=1e-9)
    s4 = rows["S4 per arc-minute of own-shaft angle (S5 = 100)"].ours
    assert r["S4"] == pytest.approx(S_WEIGHT * math.log(s4 / 36.0) / math.log(1.5), rel=1e-9)
    assert r["time_nominal"] == pytest.approx((rows["unloaded time, nominal gaps (ms)"].ours - 20.0) / 3.0, rel=1e-9)


def test_fit_parameters_and_preset_writer(tmp_path) -> None:  # type: ignore[no-untyped-def]
    ps = default_params(PAPER)
    assert len(ps) == 11 and ps[3].field == "gaps.spline"
    p = Param("x", 2.0, 50.0, True)
    assert p.value(p.unit(7.0)) == pytest.approx(7.0) and p.value(0.5) == pytest.approx(10.0)
    x = np.array([pp.value(0.5) for pp in ps])
    v, tip = apply(PAPER, ps, x)
    assert v.gaps.halfshaft.nominal == pytest.approx(PAPER.gaps.halfshaft.nominal * math.sqrt(0.75))
    assert tip.ramp_s == pytest.approx(math.sqrt(0.05 * 0.5))
    out = tmp_path / "fitted.toml"
    out.write_text(fitted_toml(FitResult(ps, x, 1.0, 1, v, tip), "row table", PAPER))
    assert load_tip_in(str(out)) == tip
    back = load_vehicle(out)
    assert back.gaps.halfshaft.nominal == v.gaps.halfshaft.nominal and back.name == "paper_fitted"
    assert out.read_text().startswith("# FITTED")


def test_fitted_preset_meets_its_targets_on_the_papers_quantities() -> None:
    """The stored fit (sim/presets/paper_fitted.toml with its [tip_in]): every fluctuation within 15 %,
    the rise within 15 %, gaps 4+5 removed within 15-25 %, two of three times in their bands; the
    misses are the ones docs/simulation.md lists (half-torque time, S1..S4 per arc-minute)."""
    v, tip = load_vehicle("paper_fitted"), load_tip_in("paper_fitted")
    assert tip is not None and tip.end_nm > 0 > tip.start_nm
    rows, cases = reproduce(v, tip)
    by = {r.quantity: r for r in rows}
    passing = [r.quantity for r in rows if r.ok]
    for key in ("fluctuation peak-valley, nominal gaps (rpm)", "fluctuation peak-valley, all gaps halved (rpm)",
                "fluctuation peak-valley, torque halved (rpm)", "speed rise while unloaded, nominal (rpm)",
                "unloaded time, nominal gaps (ms)", "unloaded time, all gaps halved (ms)",
                "gaps 4+5 eliminated: peak-valley / nominal (%)", "gaps 1+2+3 eliminated: peak-valley / nominal (%)",
                "gap 1 eliminated: change in peak-valley (rpm)", "gap 2 eliminated: change in peak-valley (rpm)",
                "gap 3 eliminated: change in peak-valley (rpm)",
                "sensitivity ranking S1<..<S5 (per arc-minute of own-shaft angle)"):
        assert key in passing, (key, by[key].ours)
    assert len(passing) == 15
    assert by["fluctuation peak-valley, nominal gaps (rpm)"].ours == pytest.approx(232, abs=3)
    assert by["unloaded time, torque halved (ms)"].ours == pytest.approx(30.2, abs=0.5)  # the documented miss
    # the fitted gap-free response is small: that is what lets gaps 4+5 removed reach ~20 %
    assert cases["zero_gaps"].fluct_rpm < 0.3 * cases["nominal"].fluct_rpm
    # the arc-minute reading keeps S1 < S2 < S3; per mm the spline's radius still ranks S1 above S2
    am = sensitivities(v, cases, per="arcmin", quantity="fluctuation")
    mm = sensitivities(v, cases, per="mm", quantity="fluctuation")
    assert am[0] < am[1] < am[2] and mm[0] > mm[1]
