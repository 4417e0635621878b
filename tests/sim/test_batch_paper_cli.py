"""Batch equals single runs; tolerance analysis; the paper reproduction and the CLI."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli import main
from sim import ParameterError, WhatIf, load_vehicle, simulate
from sim.batch import simulate_batch, tolerance_analysis, tolerance_sample
from sim.paper import reproduce, sensitivities, sensitivity_table, sensitivity_unit, tip_in_torque

PAPER = load_vehicle("paper")


def test_batch_matches_single_runs() -> None:
    t, q = tip_in_torque(duration_s=0.4)
    variants = [{}, {"gaps.halfshaft": 0.0}, {"halfshaft.stiffness": 6000.0, "body.mass": 1900.0}]
    batch = simulate_batch(PAPER, variants, t, q, interp="linear")
    for k, change in enumerate(variants):
        single = simulate(PAPER.with_changes(change), t, q, interp="linear")
        assert np.allclose(batch.motor_speed_rpm[k], single.motor_speed_rpm, atol=1e-9)
        assert batch.gap_events[k] == single.gap_events
    with pytest.raises(ParameterError, match="topology"):
        simulate_batch(PAPER, [{}, {"halfshaft.segments": 3}], t, q)
    with pytest.raises(ParameterError, match=r"variants\[1\]"):
        simulate_batch(PAPER, [{}, {"body.mass": -1.0}], t, q)


@pytest.mark.parametrize("model", ["multibody", "two_inertia"])
def test_the_motor_torque_gain_scales_the_logged_torque(model: str) -> None:
    """``[motor] torque_gain`` is the air-gap torque per logged N m: a vehicle with gain 0.8 driven by ``q`` runs
    exactly as the file's vehicle driven by ``0.8 q``, in ``simulate`` and in the batch."""
    t, q = tip_in_torque(duration_s=0.4)
    geared = PAPER.with_changes({"motor.torque_gain": 0.8})
    a = simulate(geared, t, q, interp="linear", model=model)
    b = simulate(PAPER, t, 0.8 * q, interp="linear", model=model)
    assert np.array_equal(a.motor_speed_rpm, b.motor_speed_rpm)
    assert not np.allclose(a.motor_speed_rpm, simulate(PAPER, t, q, interp="linear", model=model).motor_speed_rpm)
    if model == "multibody":
        batch = simulate_batch(geared, [{}, {"body.mass": 1900.0}], t, q, interp="linear")
        assert np.allclose(batch.motor_speed_rpm[0], a.motor_speed_rpm, atol=1e-9)
        with pytest.raises(ParameterError, match="torque gain"):
            simulate_batch(PAPER, [{}, {"motor.torque_gain": 0.9}], t, q)


def test_tolerance_analysis_is_seeded_and_brackets_nominal() -> None:
    t, q = tip_in_torque(duration_s=0.5)
    a = tolerance_analysis(PAPER, t, q, n=24, seed=5, interp="linear", window=(0.1, 0.5))
    b = tolerance_analysis(PAPER, t, q, n=24, seed=5, interp="linear", window=(0.1, 0.5))
    assert np.array_equal(a.fluct_rpm, b.fluct_rpm)
    lo, hi = a.band(0, 100)
    assert lo < hi
    col = a.fields.index("gaps.halfshaft")
    assert np.all((a.samples[:, col] >= PAPER.gaps.halfshaft.min) & (a.samples[:, col] <= PAPER.gaps.halfshaft.max))
    # bigger half-shaft lash -> more ripple: the sampled lash and the ripple correlate
    assert np.corrcoef(a.samples[:, col], a.fluct_rpm)[0, 1] > 0.3
    assert 0.0 <= a.percentile_of(a.nominal_fluct_rpm) <= 100.0


def test_antijerk_whatif_reduces_ripple() -> None:
    t, q = tip_in_torque(duration_s=0.6)
    base = simulate(PAPER, t, q, interp="linear")
    shaped = simulate(PAPER, t, q, interp="linear", what_if=WhatIf(antijerk_rate=200.0, antijerk_band=30.0))
    from sim.metrics import peak_to_valley

    assert peak_to_valley(shaped.t, shaped.motor_speed_rpm) < 0.8 * peak_to_valley(base.t, base.motor_speed_rpm)


def test_reproduce_paper_targets() -> None:
    """The paper preset with its own ramp: the gap-traverse times it was built for; the impact-induced
    sensitivity that app.pipeline reports (a lashscope quantity, not a paper row) follows the geometry."""
    rows, cases = reproduce(PAPER)
    by = {r.quantity: r for r in rows}
    for key in ("unloaded time, nominal gaps (ms)", "unloaded time, all gaps halved (ms)",
                "unloaded time, torque halved (ms)", "gap 1 eliminated: change in peak-valley (rpm)",
                "gap 3 eliminated: change in peak-valley (rpm)"):
        assert by[key].ok, (key, by[key].ours)
    assert cases["zero_gaps"].unloaded_ms == 0.0
    assert sensitivity_unit(PAPER) == "mm"
    per_mm, per_rad = sensitivities(PAPER, cases), sensitivities(PAPER, cases, per="rad")
    radii = np.array(PAPER.gap_radii_mm)
    assert np.allclose(per_mm, per_rad * radii[-1] / radii)
    # a lumped chain: a gap's effect follows the motor angle it costs, k_i / r_i per mm
    cost = np.array(PAPER.motor_angle_per_mm)
    assert np.allclose(per_mm, 100 * cost / cost[-1], rtol=0.15)
    detail = sensitivity_table(PAPER, cases)
    assert "fits better" in detail and len(detail.splitlines()) == 10


def test_cli_reproduce_and_simulate(tmp_path, capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["reproduce-paper"]) == 0
    printed = capsys.readouterr().out
    assert "targets met" in printed and "S/arcmin" in printed
    assert "tip-in" in printed and "paper_fitted" in printed
    assert main(["reproduce-paper", "--json", "--vehicle", "paper"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["quantity"] for r in rows} >= {"unloaded time, nominal gaps (ms)"}
    assert all(set(r) == {"quantity", "ours", "paper", "target", "ok"} and r["ok"] in (True, False) for r in rows)
    expected, _ = reproduce(PAPER)  # --vehicle paper: no [tip_in], the default ramp
    assert [r["ours"] for r in rows] == pytest.approx([r.ours for r in expected])
    csv_in = tmp_path / "torque.csv"
    t, q = tip_in_torque(duration_s=0.4)
    csv_in.write_text("t_s,torque_nm\n" + "".join(f"{a},{b}\n" for a, b in zip(t, q, strict=True)))
    out = tmp_path / "out.csv"
    assert main(["simulate", str(csv_in), "--interp", "linear", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "unloaded intervals" in text
    assert out.read_text().splitlines()[0].startswith("t_s,motor_speed_rpm")
    bad = tmp_path / "bad.csv"
    bad.write_text("time,torque\n0,1\n")
    assert main(["simulate", str(bad)]) == 2
    assert main(["simulate", str(csv_in), "--vehicle", "nosuch"]) == 2


def test_a_tolerance_sample_drawn_once_gives_the_same_results() -> None:
    t, q = tip_in_torque(duration_s=0.5)
    sample = tolerance_sample(PAPER, 24, 5)
    assert not sample.samples.flags.writeable
    for window in ((0.1, 0.5), (0.2, 0.4)):
        a = tolerance_analysis(PAPER, t, q, n=24, seed=5, interp="linear", window=window)
        b = tolerance_analysis(PAPER, t, q, interp="linear", window=window, sample=sample)
        assert np.array_equal(a.fluct_rpm, b.fluct_rpm) and np.array_equal(a.unloaded_ms, b.unloaded_ms)
        assert np.array_equal(a.samples, b.samples) and a.fields == b.fields
    with pytest.raises(ValueError, match="another vehicle"):
        tolerance_analysis(load_vehicle("paper"), t, q, sample=sample)
