"""The ``flexible_coupling`` stage kind (sim/stagekinds/flexible_coupling.py): a rubber coupling, no lash.

Added as one module and this test: it loads, is checked, wires into the kernel and is documented
through the registry alone.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from sim import ParameterError, Vehicle, dump_toml, load_vehicle_text, simulate
from sim.linear import modal_frequencies_hz
from sim.model import build_chain
from tests.sim.test_stages import preset_data

J_ROTOR, J_COUPLING, J_WHEEL, MASS, RADIUS = 0.05, 0.01, 0.5, 100.0, 0.3


def rig(**coupling: Any) -> dict[str, Any]:
    """Rotor -> rubber coupling -> wheels (no gears, no housing): a two-mass oscillator."""
    stage = {"kind": "flexible_coupling", "name": "rubber", "stiffness": 2000.0, "damping": 4.0,
             "inertia": J_COUPLING} | coupling
    return {"name": "rig", "motor": {"rotor_inertia": J_ROTOR}, "wheel": {"inertia": J_WHEEL, "radius": RADIUS},
            "body": {"mass": MASS}, "stage": [stage]}


def test_rubber_coupling_step_response_is_the_two_mass_oscillator() -> None:
    """A torque step through the coupling: its torque follows the analytic damped two-mass response."""
    k, c, torque = 2000.0, 4.0, 50.0
    v = Vehicle.from_dict(rig(stiffness=k, damping=c))
    j1, j2 = J_ROTOR, J_COUPLING + J_WHEEL + MASS * RADIUS**2
    j_eff = j1 * j2 / (j1 + j2)
    wn = math.sqrt(k / j_eff)
    zeta = c / (2.0 * math.sqrt(k * j_eff))
    wd = wn * math.sqrt(1.0 - zeta**2)
    assert 0.1 < zeta < 0.3 and 25.0 < wn / (2 * math.pi) < 40.0  # a well damped rubber coupling at ~32 Hz
    assert modal_frequencies_hz(build_chain(v))[-1] == pytest.approx(wn / (2 * math.pi), rel=1e-9)

    t0 = 0.05
    t = np.arange(0.0, 0.4, 0.001)
    q = np.where(t >= t0 - 1e-12, torque, 0.0)
    res = simulate(v, t, q, dt=2e-6, output_dt=1e-4)
    s = res.t - t0
    after = s >= 0.0
    # relative angle: J_eff d'' + c d' + k d = T J_eff / J1, from rest
    d_s = torque * j_eff / (j1 * k)
    env = np.exp(-zeta * wn * s[after])
    d = d_s * (1.0 - env * (np.cos(wd * s[after]) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * s[after])))
    d_dot = d_s * wn / math.sqrt(1 - zeta**2) * env * np.sin(wd * s[after])
    expected = k * d + c * d_dot
    got = res.coupling_torques["rubber"][after]
    assert np.max(np.abs(got - expected)) < 0.01 * torque * j2 / (j1 + j2)
    assert np.ptp(got) > 0.9 * torque  # the overshoot was compared, not a flat line
    assert np.all(np.abs(res.coupling_torques["rubber"][~after]) < 1e-9)
    assert res.gap_events == [] and res.gap_open == {}  # no lash: nothing opens


def test_same_arrays_as_a_lash_free_spline_but_no_gap() -> None:
    flex = Vehicle.from_dict(rig())
    spline = Vehicle.from_dict(rig(kind="spline", lash_rad=0.0))
    a, b = build_chain(flex), build_chain(spline)
    for name in ("inertia", "ck", "cc", "chalf", "cr", "ce", "creport", "ck3"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.coupling_names == b.coupling_names == ("rubber",)
    assert flex.gap_names == () and spline.gap_names == ("rubber",)
    assert a.gap_coupling == {} and b.gap_coupling == {"rubber": 0}


def test_fields_are_checked_by_its_kind() -> None:
    with pytest.raises(ParameterError, match=r"^stage 0 'rubber': lash_rad = 0.01: not a field of a "
                                             r"flexible_coupling stage; known: \["):
        Vehicle.from_dict(rig(lash_rad=0.01))
    data = rig()
    del data["stage"][0]["damping"]
    with pytest.raises(ParameterError, match=r"^stage 0 'rubber': damping = None: required field missing for a "
                                             r"flexible_coupling stage"):
        Vehicle.from_dict(data)
    with pytest.raises(ParameterError, match=r"^stage 0 'rubber': stiffness = -5.0: must be > 0"):
        Vehicle.from_dict(rig(stiffness=-5.0))
    with pytest.raises(ParameterError, match=r"cubic_stiffness = -1.0: must be >= 0"):
        Vehicle.from_dict(rig(cubic_stiffness=-1.0))


def _chain_drive_with_rubber() -> dict[str, Any]:
    data = preset_data("chain_drive")
    data["stage"].insert(1, {"kind": "flexible_coupling", "name": "rubber", "stiffness": 4000.0, "damping": 6.0,
                             "inertia": 0.002})
    data["tolerances"]["stage.rubber.stiffness"] = [3000.0, 5000.0]
    return data


def test_in_a_real_chain_it_softens_the_shuffle_and_round_trips() -> None:
    base = Vehicle.from_dict(preset_data("chain_drive"))
    v = Vehicle.from_dict(_chain_drive_with_rubber())
    assert v.stage("rubber").kind == "flexible_coupling" and v.gap_names == base.gap_names
    again = load_vehicle_text(dump_toml(v))
    assert again == v and again.to_dict() == v.to_dict()
    f_base, f_rubber = modal_frequencies_hz(build_chain(base)), modal_frequencies_hz(build_chain(v))
    first = lambda f: f[f > 0.5][0]  # noqa: E731  # first elastic mode
    assert first(f_rubber) < 0.95 * first(f_base)  # a soft element in series lowers the shuffle mode
    with pytest.raises(ParameterError, match="no such gap"):
        v.with_changes({"gaps.rubber": 0.0})
    assert v.with_changes({"stage.rubber.stiffness": 4500.0}).stage("rubber").stiffness == 4500.0
