"""Dynamics of the new topologies: unequal half-shafts through an open differential, agreement
with the solve_ivp reference, what-if and tolerance on stage names, the CLI and service paths."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from sim import ParameterError, Vehicle, WhatIf, load_vehicle, simulate
from sim.batch import tolerance_analysis
from sim.metrics import peak_to_valley
from sim.model import build_chain
from sim.paper import tip_in_torque
from sim.reference import solve_reference
from sim.simulate import RPM
from sim.whatif import parse_what_if
from tests.sim.test_stages import preset_data


def unequal_chain_drive() -> Vehicle:
    """chain_drive with a right shaft twice as stiff, less damped and with less lash than the left."""
    data = preset_data("chain_drive")
    data["stage"][4]["right"] = {"stiffness": 8000.0, "damping": 2.0, "inertia": 0.003, "lash_rad": 0.004}
    return Vehicle.from_dict(data)


def test_unequal_halfshafts_differ_in_transient_and_share_equally_in_steady_state() -> None:
    v = unequal_chain_drive()
    m = build_chain(v)
    assert m.wheel2 >= 0 and m.body_names[m.wheel] == "wheel_left" and m.body_names[m.wheel2] == "wheel_right"
    assert v.gap_names == ("motor_shaft", "chain", "differential", "halfshaft", "halfshaft_right")
    t = np.array([0.0, 0.3, 0.36, 3.0])
    q = np.array([-20.0, -20.0, 120.0, 120.0])  # tip-in through both shafts' lash, then a long steady hold
    r = simulate(v, t, q, interp="linear", speed0_rpm=2500.0)
    left, right = r.coupling_torques["halfshaft"], r.coupling_torques["halfshaft_right"]
    transient = (r.t > 0.3) & (r.t < 0.8)
    steady = r.t > 2.7
    # the open differential splits torque equally at the side gears; the shafts differ only by what
    # the side gears' own inertia takes while they swing against each other (the asymmetric mode)
    diff_transient = np.max(np.abs(left - right)[transient])
    assert diff_transient > 2.0 and diff_transient > 100 * np.max(np.abs(left - right)[steady])
    share = 0.5 * r.coupling_torques["differential"][steady]
    assert np.allclose(left[steady], right[steady], rtol=5e-3)
    assert np.allclose(left[steady], share, rtol=2e-2)  # each shaft carries half the differential's torque
    assert np.mean(left[steady]) == pytest.approx(120.0 * 42 / 11 / 2, rel=0.1)
    w_l, w_r = r.body_speeds_rpm["wheel_left"], r.body_speeds_rpm["wheel_right"]
    assert np.max(np.abs(w_l - w_r)[steady]) < 0.5  # the free asymmetric mode only drifts slowly


def test_equal_right_shaft_matches_the_lumped_pair() -> None:
    data = preset_data("chain_drive")
    lumped = Vehicle.from_dict(data)
    hs = data["stage"][4]
    data["stage"][4]["right"] = {k: hs[k] for k in ("stiffness", "damping", "inertia", "lash_rad")}
    split = Vehicle.from_dict(data)
    t, q = tip_in_torque(0.4, duration_s=0.5)
    a, b = simulate(lumped, t, q, speed0_rpm=2500.0), simulate(split, t, q, speed0_rpm=2500.0)
    assert np.ptp(a.motor_speed_rpm) > 50.0
    assert np.max(np.abs(a.motor_speed_rpm - b.motor_speed_rpm)) < 0.05  # symmetric motion: the same model
    assert np.allclose(b.coupling_torques["halfshaft"], b.coupling_torques["halfshaft_right"], atol=1e-6)
    assert np.allclose(a.coupling_torques["halfshaft"], b.coupling_torques["halfshaft"], atol=0.05)


@pytest.mark.parametrize("vehicle", ["single_reduction", "chain_drive", "unequal"])
def test_new_topologies_agree_with_the_solve_ivp_reference(vehicle: str) -> None:
    v = unequal_chain_drive() if vehicle == "unequal" else load_vehicle(vehicle)
    t, q = tip_in_torque(0.6, duration_s=0.4)
    res = simulate(v, t, q, interp="linear", speed0_rpm=2000.0)
    m = build_chain(v)
    fine = np.arange(0.0, 0.4, 2e-5)
    _, omega, _ = solve_reference(m, t, q, True, 2000.0 / RPM, fine, rtol=1e-8, atol=1e-9)
    ref = (omega[:, m.rotor] - (omega[:, m.housing] if m.housing >= 0 else 0.0)) * RPM
    ours = res.motor_speed_rpm
    ref_on_grid = np.interp(res.t, fine, ref)
    assert peak_to_valley(res.t, ours, 0.05, 0.4) > 30.0  # a real shuffle
    assert np.max(np.abs(ours - ref_on_grid)) < 3.0  # a slight phase lag at most, not a different shuffle
    assert peak_to_valley(res.t, ours, 0.05, 0.4) == pytest.approx(peak_to_valley(res.t, ref_on_grid, 0.05, 0.4),
                                                                   abs=1.0)


def test_what_if_and_tolerance_use_stage_names() -> None:
    v = load_vehicle("chain_drive")
    no_chain = parse_what_if(["gap=chain:0"]).apply_vehicle(v)
    assert no_chain.gap("chain").nominal == 0.0 and no_chain.gap("halfshaft").nominal == v.gap("halfshaft").nominal
    assert no_chain.gap("chain").min == 0.0 and no_chain.gap("chain").max == v.gap("chain").max
    with pytest.raises(ParameterError, match=r"what_if\.gap_scale\.mesh1 = 0\.5: unknown gap; known: \['motor_shaft'"):
        WhatIf(gap_scale={"mesh1": 0.5}).apply_vehicle(v)
    assert v.with_changes({"stage.chain.stiffness": 2.5e4}).stage("chain").stiffness == 2.5e4
    with pytest.raises(ParameterError, match=r"stage\.sprocket = 'sprocket': no such stage"):
        v.with_changes({"stage.sprocket.stiffness": 1.0})
    u = unequal_chain_drive()
    half = WhatIf(gap_scale={"halfshaft_right": 0.5}).apply_vehicle(u)
    assert half.gap("halfshaft_right").nominal == pytest.approx(0.002) and half.gap("halfshaft").nominal == 0.010
    t, q = tip_in_torque(0.5, duration_s=0.35)
    tol = tolerance_analysis(v, t, q, n=6, seed=3, window=(0.05, 0.35))
    assert "gaps.chain" in tol.fields and "stage.chain.stiffness" in tol.fields
    assert tol.fluct_rpm.shape == (6,) and np.all(tol.fluct_rpm > 0) and np.ptp(tol.fluct_rpm) > 0.5


def test_effects_on_a_chain_drive() -> None:
    from sim.effects import applicable_effects, apply_effects
    from sim.effects.backlash import gap_groups

    v = unequal_chain_drive()
    assert gap_groups(v) == (("motor_shaft", "chain", "differential"), ("halfshaft", "halfshaft_right"))
    reasons = applicable_effects(v)
    assert "no drive-unit housing" in reasons["housing_mount"] and "unequal" in reasons["tyre_slip"]
    assert reasons["backlash"] == "" and reasons["drag"] == ""
    w = apply_effects(v, {"backlash": {"reducer_scale": 0.5, "halfshaft_scale": 2.0},
                          "housing_mount": {"stiffness_log2": 1.0}, "progressive_stiffness": {"halfshaft_rel": 1.0}})
    assert w.gap("chain").nominal == pytest.approx(0.0095) and w.gap("halfshaft_right").nominal == pytest.approx(0.008)
    assert not w.housing.enabled  # housing_mount did not apply: nothing switched on
    assert w.stage("halfshaft").cubic_stiffness == pytest.approx(4000.0 / 0.01)
    assert w.stage("halfshaft").right is not None and w.stage("halfshaft").right.cubic_stiffness == pytest.approx(8e5)


def test_cli_simulates_a_stage_preset(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    csv_in = tmp_path / "torque.csv"
    t, q = tip_in_torque(0.5, duration_s=0.4)
    csv_in.write_text("t_s,torque_nm\n" + "".join(f"{a},{b}\n" for a, b in zip(t, q, strict=True)))
    out = tmp_path / "out.csv"
    assert main(["simulate", str(csv_in), "--vehicle", "chain_drive", "--out", str(out),
                 "--what-if", "gap=chain:0.5"]) == 0
    assert "unloaded intervals" in capsys.readouterr().out
    rows = out.read_text().splitlines()
    assert rows[0].startswith("t_s,motor_speed_rpm") and len(rows) > 300
    assert main(["simulate", str(csv_in), "--vehicle", "chain_drive", "--what-if", "gap=mesh1:0.5"]) == 2
    assert "unknown gap" in capsys.readouterr().err


def test_service_accepts_every_preset(tmp_path: Path) -> None:
    """The REST route stores a preset as its TOML (``dump_toml``) and checks it as a user file."""
    from app.api.routes.vehicles import _preset_toml
    from app.pipeline import check_vehicle_files
    from tests.conftest import REPO

    for name in ("paper", "single_reduction", "chain_drive"):
        path = tmp_path / f"{name}.toml"
        path.write_text(_preset_toml(name), encoding="utf-8")
        summary: dict[str, Any] = check_vehicle_files(path, REPO / "dbc" / "lashscope_ev.dbc",
                                                      REPO / "dbc" / "lashscope_ev.map.toml")
        assert summary["vehicle"] == name and summary["ratio"] == pytest.approx(load_vehicle(name).ratio)
        assert 1e3 < summary["steps_per_simulated_s"] < 1e6
        assert summary["stages"][-1].startswith("halfshaft")


def test_gap_sensitivity_two_inertia_and_free_inertia_on_a_chain_drive() -> None:
    from app.pipeline import free_rotor_inertia, gap_sensitivity

    v = load_vehicle("chain_drive")
    doc = gap_sensitivity(v)
    rows = {r["gap"]: r for r in doc["gaps"]}
    assert list(rows) == ["motor_shaft", "chain", "differential", "halfshaft"]
    assert doc["sensitivity_unit"] == "rad"  # not every stage gives a contact radius
    assert rows["halfshaft"]["sensitivity"] == pytest.approx(100.0) and "halfshaft = 100" in doc[
        "sensitivity_definition"]
    assert rows["chain"]["nominal_rad"] == 0.019 and rows["chain"]["removed"]["impact_rpm"] != doc["nominal"][
        "impact_rpm"]
    # rotor, motor shaft, sprocket + case and side gears, each times its squared speed ratio to the rotor
    m = build_chain(v)
    expected = 0.0383 + 0.0008 + 0.015 / (42 / 11) ** 2 + (0.0012 + 2 * 0.002 / 2) / (42 / 11) ** 2
    assert free_rotor_inertia(v) == pytest.approx(expected, rel=1e-9) and m.n_bodies == 5
    t, q = np.array([0.0, 2.0]), np.array([60.0, 60.0])
    for veh in (v, unequal_chain_drive()):
        two = simulate(veh, t, q, model="two_inertia", speed0_rpm=2000.0, output_dt=0.002)
        multi = simulate(veh, t, q, speed0_rpm=2000.0, output_dt=0.002)
        gain_two, gain_multi = two.motor_speed_rpm[-1] - 2000.0, multi.motor_speed_rpm[-1] - 2000.0
        assert gain_multi > 300.0  # 60 N m on a 300 kg car for 2 s
        # the lumped model accelerates alike; it leaves out only the Coulomb drag (~0.6 N m at the rotor)
        assert gain_two == pytest.approx(gain_multi, rel=0.03)


def test_too_costly_stage_chain_names_the_stage_field() -> None:
    from app.vehicle_check import suspect_fields, trial_vehicle

    assert suspect_fields(load_vehicle("chain_drive")) == []
    v = load_vehicle("chain_drive").with_changes({"stage.motor_shaft.inertia": 1e-6,
                                                  "stage.motor_shaft.stiffness": 1e8})
    # compared with the paper's stage of the same kind (its spline: 3e4 N m/rad, 0.0015 kg m^2)
    assert suspect_fields(v) == [("stage.motor_shaft.stiffness", 1e8, 3e4), ("stage.motor_shaft.inertia", 1e-6, 0.0015)]
    with pytest.raises(ParameterError, match=r"^stage\.motor_shaft\.stiffness = 100000000\.0: driveline car\.toml "
                                             r"needs 1\.\d+e\+07 integrator steps"):
        trial_vehicle(v, "car.toml")
