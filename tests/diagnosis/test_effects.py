from __future__ import annotations

import numpy as np
import pytest

from sim import ParameterError, load_vehicle, simulate
from sim.effects import EFFECTS, apply_effects, get_effect


def test_library_has_bounded_small_effects() -> None:
    assert {"backlash", "housing_mount", "torque_lag", "speed_sensor", "drag"} <= set(EFFECTS)
    for eff in EFFECTS.values():
        assert 1 <= len(eff.params) <= 3
        for p in eff.params:
            assert p.lo < p.hi and p.lo <= p.off <= p.hi
        assert eff.describe()["params"]


@pytest.mark.parametrize("eid", sorted(EFFECTS))
def test_off_values_leave_the_vehicle_unchanged(eid: str) -> None:
    v = load_vehicle("paper")
    assert apply_effects(v, {eid: get_effect(eid).off_values()}).to_dict() == v.to_dict()


@pytest.mark.parametrize(("eid", "values", "field", "expected"), [
    ("torque_lag", {"tau_s": 0.02, "delay_s": 0.005}, "effects.torque_lag.tau_s", 0.02),
    ("speed_sensor", {"tau_s": 0.01, "delay_s": 0.002}, "effects.speed_sensor.delay_s", 0.002),
    ("drag", {"coulomb_nm": 3.0, "viscous_nms": 0.01}, "effects.drag.coulomb_nm", 3.0),
    ("backlash", {"reducer_scale": 1.0, "halfshaft_scale": 1.5}, "gaps.halfshaft", 1.5),
    ("housing_mount", {"stiffness_log2": 1.0, "damping_log2": 0.0}, "housing.mount_stiffness", 2.0),
])
def test_effects_act_through_the_model_parameters(eid: str, values: dict[str, float], field: str,
                                                  expected: float) -> None:
    """Absolute values for the effect's own fields; factors on the preset's value for scaled fields."""
    base = load_vehicle("paper")
    v = apply_effects(base, {eid: values})
    scaled = field.startswith(("gaps.", "housing."))
    assert v.get(field) == pytest.approx(expected * base.get(field) if scaled else expected)


def test_an_effect_changes_the_simulated_speed() -> None:
    v = load_vehicle("paper")
    t = np.arange(0.0, 0.6, 0.01)
    tq = np.interp(t, [0.0, 0.2, 0.3, 0.6], [-50.0, -50.0, 150.0, 150.0])
    a = simulate(v, t, tq, speed0_rpm=2000.0, interp="linear")
    b = simulate(apply_effects(v, {"torque_lag": {"tau_s": 0.02, "delay_s": 0.0}}), t, tq, speed0_rpm=2000.0,
                 interp="linear")
    assert np.max(np.abs(a.motor_speed_rpm - b.motor_speed_rpm)) > 5.0


def test_values_outside_the_prior_and_unknown_effects_are_rejected() -> None:
    with pytest.raises(ParameterError, match="prior range"):
        get_effect("torque_lag").values({"tau_s": 0.5})
    with pytest.raises(ParameterError, match="known: backlash"):
        get_effect("gremlins")
    with pytest.raises(ParameterError, match="unknown parameters"):
        get_effect("drag").values({"coulomb": 1.0})
