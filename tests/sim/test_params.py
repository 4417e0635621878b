"""Vehicle file: presets, round trips, validation errors naming field and value, what-if changes."""

from __future__ import annotations

import json

import pytest

from sim import ParameterError, Vehicle, dump_toml, load_vehicle, load_vehicle_text, preset_names
from sim.params import GAP_NAMES


def test_paper_preset_gears_and_ratio() -> None:
    v = load_vehicle("paper")
    assert "paper" in preset_names()
    assert v.reducer.teeth == (27, 79, 20, 77)
    assert v.ratio == pytest.approx(79 / 27 * 77 / 20)
    assert 11.2 < v.ratio < 11.3
    for g in GAP_NAMES:  # nominal is the tolerance-band midpoint
        gap = getattr(v.gaps, g)
        assert gap.nominal == pytest.approx((gap.min + gap.max) / 2)


def test_dict_json_and_toml_round_trip() -> None:
    v = load_vehicle("paper")
    assert Vehicle.from_dict(v.to_dict()) == v
    assert Vehicle.from_dict(json.loads(json.dumps(v.to_dict()))) == v
    assert load_vehicle_text(dump_toml(v)) == v
    assert load_vehicle_text(json.dumps(v.to_dict())) == v


def test_load_from_path(tmp_path) -> None:  # type: ignore[no-untyped-def]
    p = tmp_path / "car.toml"
    p.write_text(dump_toml(load_vehicle("paper").with_changes({"body.mass": 2000.0})))
    assert load_vehicle(str(p)).body.mass == 2000.0


@pytest.mark.parametrize(
    ("path", "value", "field"),
    [
        ("halfshaft.stiffness", -5.0, "halfshaft.stiffness"),
        ("motor.rotor_inertia", 0.0, "motor.rotor_inertia"),
        ("gaps.halfshaft.nominal", -0.01, "gaps.halfshaft.nominal"),
        ("halfshaft.segments", 0, "halfshaft.segments"),
        ("housing.enabled", "yes", "housing.enabled"),
        ("body.mass", "heavy", "body.mass"),
        ("body.mass", float("nan"), "body.mass"),
    ],
)
def test_invalid_field_names_field_and_value(path: str, value: object, field: str) -> None:
    data = load_vehicle("paper").to_dict()
    node = data
    parts = path.split(".")
    for p in parts[:-1]:
        node = node[p]
    node[parts[-1]] = value
    with pytest.raises(ParameterError) as err:
        Vehicle.from_dict(data)
    assert err.value.field == field
    assert repr(value) in str(err.value) or str(value) in str(err.value)


def test_unknown_missing_and_band_errors() -> None:
    data = load_vehicle("paper").to_dict()
    data["motor"]["colour"] = "red"
    with pytest.raises(ParameterError, match=r"motor\.colour"):
        Vehicle.from_dict(data)
    data = load_vehicle("paper").to_dict()
    del data["wheel"]["radius"]
    with pytest.raises(ParameterError, match=r"wheel\.radius"):
        Vehicle.from_dict(data)
    data = load_vehicle("paper").to_dict()
    data["gaps"]["mesh1"]["min"] = 0.01
    with pytest.raises(ParameterError, match=r"gaps\.mesh1\.min"):
        Vehicle.from_dict(data)
    with pytest.raises(ParameterError, match="nosuch"):
        load_vehicle("nosuch")
    with pytest.raises(ParameterError, match="TOML"):
        load_vehicle_text("name = ")
    data = load_vehicle("paper").to_dict()
    data["tolerances"]["body.mass"] = [2000.0, 1000.0]
    with pytest.raises(ParameterError, match=r"tolerances\.body\.mass"):
        Vehicle.from_dict(data)
    data["tolerances"] = {"body.colour": [0.0, 1.0]}
    with pytest.raises(ParameterError, match=r"body\.colour"):
        Vehicle.from_dict(data)


def test_with_changes() -> None:
    v = load_vehicle("paper")
    w = v.with_changes({"gaps.halfshaft": 0.0}, body__mass=2000.0)
    assert w.gaps.halfshaft.nominal == 0.0 and w.body.mass == 2000.0
    assert w.gaps.halfshaft.max == v.gaps.halfshaft.max  # band kept
    assert v.body.mass != 2000.0  # original untouched
    with pytest.raises(ParameterError, match="no such"):
        v.with_changes({"motor.colour": 1.0})
    assert v.get("halfshaft.stiffness") == v.halfshaft.stiffness


def test_gap_contact_radius_and_mm_input() -> None:
    """Gaps in mm of circumferential clearance convert through the contact radius; errors name the field."""
    v = load_vehicle("paper")
    assert v.gaps.mesh1.radius_mm == pytest.approx(128.4 / 2)  # Table 1 pitch diameters
    assert v.gaps.mesh2.radius_mm == pytest.approx(198.2 / 2)
    assert v.gaps_mm[2] == pytest.approx(v.gaps.mesh2.nominal * 99.1)
    r1, r2 = v.reducer.ratio1, v.reducer.ratio2
    cost = v.motor_angle_per_mm
    assert cost[1] == pytest.approx(r1 / 64.2) and cost[4] == pytest.approx(r1 * r2 / v.gaps.halfshaft.radius_mm)
    data = v.to_dict()
    data["gaps"]["mesh2"] = {"radius_mm": 99.1, "nominal_mm": 0.1, "min_mm": 0.05, "max_mm": 0.15}
    w = Vehicle.from_dict(data)
    assert w.gaps.mesh2.nominal == pytest.approx(0.1 / 99.1) and w.gaps.mesh2.max == pytest.approx(0.15 / 99.1)
    assert w.gaps.mesh2.arc_mm() == pytest.approx(0.1)
    assert load_vehicle_text(dump_toml(w)) == w  # written back in rad, read back equal
    text = dump_toml(v).replace("[gaps.mesh1]\nnominal = 0.0026", "[gaps.mesh1]\nnominal_mm = 0.2")
    assert load_vehicle_text(text).gaps.mesh1.nominal == pytest.approx(0.2 / 64.2)
    data["gaps"]["mesh2"] = {"radius_mm": 99.1, "nominal_mm": 0.1, "nominal": 0.001}
    with pytest.raises(ParameterError, match=r"gaps\.mesh2\.nominal_mm.*not both"):
        Vehicle.from_dict(data)
    data["gaps"]["mesh2"] = {"nominal_mm": 0.1}
    with pytest.raises(ParameterError, match=r"gaps\.mesh2\.radius_mm"):
        Vehicle.from_dict(data)
    data["gaps"]["mesh2"] = {"radius_mm": 99.1, "nominal_mm": -0.1}
    with pytest.raises(ParameterError, match=r"gaps\.mesh2\.nominal_mm = -0\.1"):
        Vehicle.from_dict(data)
    # what-ifs in mm, with the radius changed in the same call
    u = v.with_changes({"gaps.differential.nominal_mm": 0.3, "gaps.differential.radius_mm": 30.0})
    assert u.gaps.differential.nominal == pytest.approx(0.01) and u.gaps.differential.arc_mm() == pytest.approx(0.3)
    bare = Vehicle.from_dict({**v.to_dict(), "gaps": {g: 0.01 for g in GAP_NAMES}})
    assert bare.gap_radii_mm == (0.0,) * 5
    with pytest.raises(ParameterError, match=r"gaps\.spline\.radius_mm"):
        _ = bare.gaps_mm


def test_optional_effect_fields_validate() -> None:
    v = load_vehicle("paper")
    assert not v.effects.progressive_stiffness.any and not v.effects.tyre_slip.enabled
    w = v.with_changes({"effects.progressive_stiffness.halfshaft": 2.0e6, "effects.tyre_slip.enabled": True})
    assert w.effects.progressive_stiffness.any and load_vehicle_text(dump_toml(w)) == w
    with pytest.raises(ParameterError, match=r"effects\.progressive_stiffness\.mount = -1\.0: must be >= 0"):
        v.with_changes({"effects.progressive_stiffness.mount": -1.0})
    with pytest.raises(ParameterError, match=r"effects\.tyre_slip\.relaxation_length = 0\.0"):
        v.with_changes({"effects.tyre_slip.relaxation_length": 0.0})
    with pytest.raises(ParameterError, match=r"effects\.tyre_slip\.enabled"):
        v.with_changes({"effects.tyre_slip.enabled": 1})
