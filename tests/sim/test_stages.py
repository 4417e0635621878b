"""Stage-chain vehicle files: loading, classic equivalence, presets, validation messages."""

from __future__ import annotations

import copy
import tomllib
from importlib import resources
from typing import Any

import numpy as np
import pytest

from sim import ParameterError, Vehicle, dump_toml, load_vehicle, simulate
from sim.model import build_chain
from sim.paper import tip_in_torque
from sim.vehicle_file import load_vehicle_text, preset_names

PAPER = load_vehicle("paper")


def preset_data(name: str) -> dict[str, Any]:
    text = (resources.files("sim") / "presets" / f"{name}.toml").read_text(encoding="utf-8")
    return tomllib.loads(text)


def test_classic_paper_and_its_stage_file_give_the_same_run() -> None:
    staged = load_vehicle_text(dump_toml(PAPER.as_stages()))
    assert staged.stages and staged.reducer is None and staged.housing.enabled
    assert [s.kind for s in staged.stages] == ["spline", "gear", "gear", "differential", "halfshaft"]
    assert staged.gap_names == PAPER.gap_names and staged.ratio == pytest.approx(PAPER.ratio, rel=1e-15)
    assert staged.motor_side_gaps == pytest.approx(PAPER.motor_side_gaps, rel=1e-15)
    assert dict(staged.tolerances)["stage.halfshaft.stiffness"] == (6800.0, 9200.0)
    a, b = build_chain(PAPER), build_chain(staged)
    for name in ("inertia", "ck", "cc", "chalf", "cr", "ce", "creport"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    t, q = tip_in_torque(duration_s=0.5)
    ra, rb = simulate(PAPER, t, q), simulate(staged, t, q)
    assert np.max(np.abs(ra.motor_speed_rpm - rb.motor_speed_rpm)) <= 0.01
    assert np.ptp(ra.motor_speed_rpm) > 100.0  # a real transient was compared
    assert ra.gap_events == rb.gap_events
    assert set(rb.coupling_torques) == {"spline", "mesh1", "mesh2", "differential", "halfshaft1", "halfshaft2", "mount"}


def test_housing_is_explicit_in_stage_files_and_classic_default_stays() -> None:
    classic = PAPER.to_dict()
    classic.pop("housing")
    assert Vehicle.from_dict(classic).housing.enabled  # stored classic vehicles do not change
    chain = load_vehicle("chain_drive")
    assert not chain.housing.enabled and "housing" not in build_chain(chain).body_names
    with_housing = preset_data("chain_drive") | {"housing": {"inertia": 0.5, "mount_stiffness": 2e4}}
    assert Vehicle.from_dict(with_housing).housing.enabled


@pytest.mark.parametrize(("preset", "ratio", "kinds"), [
    ("paper", 79 / 27 * 77 / 20, ["spline", "gear", "gear", "differential", "halfshaft"]),
    ("single_reduction", 123 / 17, ["spline", "gear", "differential", "halfshaft"]),
    ("chain_drive", 42 / 11, ["spline", "chain", "differential", "halfshaft"]),
])
def test_presets_load_and_hold_their_quasi_static_speed_ratio(preset: str, ratio: float, kinds: list[str]) -> None:
    v = load_vehicle(preset)
    assert preset in preset_names()
    assert [s.kind for s in v.chain] == kinds and v.ratio == pytest.approx(ratio, rel=1e-12)
    assert load_vehicle_text(dump_toml(v)) == v  # the file round-trips
    t = np.array([0.0, 2.0])
    q = np.array([40.0, 40.0])  # steady drive torque: after the shuffle decays, a rigid ratio
    r = simulate(v, t, q, speed0_rpm=2000.0, output_dt=0.002)
    ratio_end = r.rotor_speed_rpm[-1] / r.wheel_speed_rpm[-1]
    assert ratio_end == pytest.approx(ratio, rel=2e-4)
    assert r.rotor_speed_rpm[-1] > 2000.0  # 40 N m accelerates every preset at this speed


def test_chain_does_not_reverse_and_reacts_on_the_housing_unlike_a_gear_pair() -> None:
    base = preset_data("chain_drive") | {"housing": {"inertia": 0.5, "mount_stiffness": 2e4, "mount_damping": 50.0}}
    as_gear = copy.deepcopy(base)
    as_gear["stage"][2]["kind"] = "gear"
    chain_m, gear_m = build_chain(Vehicle.from_dict(base)), build_chain(Vehicle.from_dict(as_gear))
    j = chain_m.coupling_names.index("chain")
    r = 42 / 11
    assert chain_m.ce[j] == pytest.approx(1 - r) and gear_m.ce[j] == pytest.approx(1 + r)
    assert np.array_equal(chain_m.speed_ratio, gear_m.speed_ratio)  # same speeds in drive sense
    mount = chain_m.coupling_names.index("mount")
    tau_c, tau_g = _static_torques(chain_m), _static_torques(gear_m)
    assert tau_c[j] == pytest.approx(tau_g[j], rel=1e-9) and 90.0 < tau_c[j] < 100.0  # T less the rotor's share
    # mount torque = -T + e tau: a chain drive rolls the housing back (~ -r T), a gear pair forward (~ +r T)
    assert tau_c[mount] == pytest.approx(-100.0 + (1 - r) * tau_c[j], rel=1e-9) and tau_c[mount] < -350.0
    assert tau_g[mount] == pytest.approx(-100.0 + (1 + r) * tau_g[j], rel=1e-9) and tau_g[mount] > 330.0


def _static_torques(m: Any) -> Any:
    """Coupling torques (N m, a side) of the quasi-static state under 100 N m at 300 rad/s."""
    from sim.model import deflections, quasi_static_full

    theta, _, _ = quasi_static_full(m, 100.0, 300.0)
    delta = deflections(m, theta)
    return m.ck * (delta - np.sign(delta) * m.chalf)


def _chain_with(stage: int, **fields: Any) -> dict[str, Any]:
    data = preset_data("chain_drive")
    data["stage"][stage].update(fields)
    return data


def _chain_without(stage: int, key: str) -> dict[str, Any]:
    data = preset_data("chain_drive")
    data["stage"][stage].pop(key)
    return data


@pytest.mark.parametrize(("data", "message"), [
    (_chain_with(2, lash_rad=-0.1), "stage 2 'chain': lash_rad = -0.1: must be >= 0"),
    (_chain_with(2, stiffness=1e30), "stage 2 'chain': stiffness = 1e+30: outside the physical range"),
    (_chain_with(2, kind="sprocket"), "stage 2 'chain': kind = 'sprocket': unknown stage kind"),
    (_chain_with(3, type="limited"), "stage 3 'differential': type = 'limited': must be one of"),
    (_chain_with(4, count=3), "stage 4 'halfshaft': count = 3: outside the physical range"),
    (_chain_with(2, teeth=[11]), "stage 2 'chain': teeth = [11]: must be [drive, driven]"),
    (_chain_with(2, ratio=3.0), "stage 2 'chain': ratio = 3.0: give exactly one of ratio or teeth"),
    (_chain_with(2, referred_to="wheel"), "stage 2 'chain': referred_to = 'wheel': must be one of"),
    (_chain_with(2, colour="red"), "stage 2 'chain': colour = 'red': not a field of a chain stage"),
    (_chain_with(2, name="housing"), "stage 2 'housing': name = 'housing': reserved"),
    (_chain_with(2, name="differential"), "stage 3 'differential': name = 'differential': already used by stage 2"),
    (_chain_with(4, right={"stiffness": 5000.0}), "stage 4 'halfshaft': right.damping = None: required field"),
    (_chain_with(2, lash_rad={"nominal": 0.02, "min": 0.03}), "stage 2 'chain': lash_rad = 0.02: must lie within"),
    (_chain_without(2, "stiffness"), "stage 2 'chain': stiffness = None: required field missing for a chain stage"),
    (_chain_without(3, "damping"), "stage 3 'differential': damping = None: required field missing"),
    (_chain_without(2, "kind"), "stage 2 'chain': kind = None: required field missing"),
    (preset_data("chain_drive") | {"tolerances": {"stage.chain.stiffness": [0.0, 4e4]}},
     "tolerances.stage.chain.stiffness[min] = 0.0: must be > 0"),
])
def test_bad_stage_fields_are_named_in_one_line(data: dict[str, Any], message: str) -> None:
    with pytest.raises(ParameterError) as exc:
        Vehicle.from_dict(data)
    text = str(exc.value)
    assert "\n" not in text and text.startswith(message), text


def _reorder(order: list[int]) -> dict[str, Any]:
    data = preset_data("chain_drive")
    data["stage"] = [data["stage"][i] for i in order]
    return data


def test_a_topology_that_is_not_a_rotor_to_wheel_chain_is_refused() -> None:
    data = preset_data("chain_drive")
    missing = []
    for drop_end, what, where in ((0, "rotor", "stage 0 'motor_shaft': kind = 'spline'"),
                                  (-1, "wheel", "stage 4 'halfshaft': kind = 'halfshaft'")):
        d = copy.deepcopy(data)
        d["stage"].pop(drop_end)
        missing.append((d, f"{where}: the chain has no {what} end"))
    two_diffs = copy.deepcopy(data)
    two_diffs["stage"].insert(4, dict(two_diffs["stage"][3], name="diff2"))
    cases = [
        *missing,
        (two_diffs, "stage 4 'diff2': kind = 'differential': second differential; stage 3 'differential'"),
        (_reorder([0, 1, 4, 2, 3, 5]), "stage 2 'halfshaft': kind = 'halfshaft': the half-shafts must be the last"),
        (_reorder([0, 1, 3, 2, 4, 5]), "stage 3 'chain': kind = 'chain': a chain stage cannot follow the "
                                       "differential 'differential'"),
        (_reorder([0, 2, 1, 3, 4, 5]) | {"motor": {"rotor_inertia": 0.04}},
         "stage 0 'rotor': kind = 'rotor': given both"),
        (_reorder([1, 0, 2, 3, 4, 5]), "stage 1 'rotor': kind = 'rotor': the rotor must be the first entry"),
        ({**data, "stage": []}, "stage = []: must be a non-empty list"),
        (data | {"reducer": PAPER.to_dict()["reducer"]}, "stage = 4: give [[stage]] tables or [reducer]"),
    ]
    for d, message in cases:
        with pytest.raises(ParameterError) as exc:
            Vehicle.from_dict(d)
        assert str(exc.value).startswith(message), (message, str(exc.value))
    # unequal half-shafts need an open differential before them
    solid = copy.deepcopy(data)
    solid["stage"][3] = {"kind": "differential", "name": "axle", "type": "solid", "inertia": 0.001}
    solid["stage"][4]["right"] = {"stiffness": 5000.0, "damping": 4.0}
    with pytest.raises(ParameterError, match=r"stage 4 'halfshaft': right = 'unequal shafts': .*open differential"):
        Vehicle.from_dict(solid)
    solid["stage"][4].pop("right")
    axle = Vehicle.from_dict(solid)  # a solid axle: the shafts start at the sprocket's body
    assert axle.gap_names == ("motor_shaft", "chain", "halfshaft") and "axle" not in build_chain(axle).body_names


def test_input_referred_values_are_converted_with_the_ratio() -> None:
    out = Vehicle.from_dict(preset_data("chain_drive"))
    data = preset_data("chain_drive")
    r = 42 / 11
    chain = data["stage"][2]
    chain.update(referred_to="input", stiffness=chain["stiffness"] / r**2, damping=chain["damping"] / r**2,
                 lash_rad={"nominal": chain["lash_rad"]["nominal"] * r, "min": chain["lash_rad"]["min"] * r,
                           "max": chain["lash_rad"]["max"] * r})
    inp = Vehicle.from_dict(data)
    a, b = build_chain(out), build_chain(inp)
    assert np.allclose(a.ck, b.ck, rtol=1e-12) and np.allclose(a.chalf, b.chalf, rtol=1e-12)
    assert inp.motor_side_gaps == pytest.approx(out.motor_side_gaps, rel=1e-12)


def test_the_documented_full_example_loads_and_runs() -> None:
    from tests.conftest import REPO

    doc = (REPO / "docs" / "simulation.md").read_text(encoding="utf-8")
    start = doc.index("```toml", doc.index("Full example"))
    v = load_vehicle_text(doc[start + len("```toml"):doc.index("```", start + 7)])
    assert [s.kind for s in v.stages] == ["spline", "planetary", "chain", "differential", "halfshaft"]
    assert v.ratio == pytest.approx(4.0 * 2.5) and v.housing.enabled
    assert v.gap_names == ("input", "planet", "chain", "diff", "shafts", "shafts_right")
    m = build_chain(v)
    assert m.ce[m.coupling_names.index("planet")] == pytest.approx(1 - 4.0)  # no reversal before it
    assert m.ce[m.coupling_names.index("chain")] == pytest.approx(1 - 2.5)
    t, q = tip_in_torque(0.3, duration_s=0.3)
    r = simulate(v, t, q, speed0_rpm=1500.0)
    assert np.ptp(r.motor_speed_rpm) > 10.0 and "shafts_right" in r.coupling_torques


def test_every_stage_value_is_reached_through_the_chain_and_the_file_s_own_field() -> None:
    paper = load_vehicle("paper")
    assert paper.field_of("halfshaft", "stiffness") == "halfshaft.stiffness"
    assert paper.field_of("mesh1", "damping") == "reducer.mesh1_damping"
    assert paper.field_of("spline", "inertia") == "reducer.input_shaft_inertia"
    assert paper.field_of("mesh2", "cubic_stiffness") == "effects.progressive_stiffness.mesh2"
    staged = paper.as_stages()
    for v in (paper, staged, load_vehicle("chain_drive"), load_vehicle("single_reduction")):
        for s in v.chain:
            for attr in ("stiffness", "damping", "cubic_stiffness"):
                if s.has_coupling:
                    assert v.get(v.field_of(s.name, attr)) == getattr(s, attr), (v.name, s.name, attr)
    assert staged.field_of("halfshaft", "stiffness") == "stage.halfshaft.stiffness"
    # a value changed through the file's own field is the chain's value, in either layout
    for v in (paper, staged):
        moved = v.with_changes({v.field_of("mesh2", "stiffness"): 1.5 * v.stage("mesh2").stiffness})
        assert moved.stage("mesh2").stiffness == 1.5 * v.stage("mesh2").stiffness
    with pytest.raises(ParameterError, match="no such stage"):
        paper.field_of("gearbox", "stiffness")
    with pytest.raises(ParameterError, match="no such stage"):
        staged.field_of("gearbox", "stiffness")
    with pytest.raises(ParameterError, match="no such field"):
        paper.field_of("halfshaft", "ratio")


def test_a_classic_file_always_describes_a_housing_and_a_stage_file_only_with_one() -> None:
    paper = load_vehicle("paper")
    assert paper.housing_described
    assert paper.with_changes({"housing.enabled": False}).housing_described
    assert not load_vehicle("chain_drive").housing.enabled
    assert not load_vehicle("chain_drive").housing_described
    assert paper.as_stages().housing_described
