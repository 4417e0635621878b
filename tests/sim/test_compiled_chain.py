"""The compiled chain belongs to the Vehicle: built once per object, read-only, shared by every run of it."""

from __future__ import annotations

import copy
import pickle
from dataclasses import fields

import numpy as np
import pytest

from sim import WhatIf, load_vehicle, simulate
from sim.batch import simulate_batch
from sim.effects import apply_effects
from sim.model import build_chain, quasi_static_full
from sim.paper import tip_in_torque
from sim.runner import run_from_state
from sim.simulate import choose_step, simulate_speed
from tests.sim.test_topologies import unequal_chain_drive


def _same(a: object, b: object) -> bool:
    return all(np.array_equal(getattr(a, f.name), getattr(b, f.name)) if isinstance(getattr(a, f.name), np.ndarray)
               else getattr(a, f.name) == getattr(b, f.name) for f in fields(a))  # type: ignore[arg-type]


def test_built_on_first_use_and_kept(chain_builds: list[str]) -> None:
    v = load_vehicle("paper")
    t, q = tip_in_torque(1.0, duration_s=0.3)
    assert chain_builds == []  # loading does not compile
    m = v.compiled
    simulate(v, t, q)
    simulate_speed(v, t, q)
    simulate(v, t, q, model="two_inertia")
    assert v.compiled is m and chain_builds == ["paper"]
    assert _same(m, build_chain(v))


def test_a_changed_vehicle_has_its_own(chain_builds: list[str]) -> None:
    v = load_vehicle("paper")
    heavy = v.with_changes({"body.mass": 2000.0})
    assert heavy.compiled is not v.compiled
    assert heavy.compiled.road[1] == 2000.0 and v.compiled.road[1] == v.body.mass
    t, q = tip_in_torque(1.0, duration_s=0.3)
    simulate(v, t, q, what_if=WhatIf(gap_scale={"all": 0.5}))  # the what-if vehicle is a new object
    simulate_batch(v, [{}, {"body.mass": 2000.0}], t, q)  # the nominal variant is the vehicle itself
    assert chain_builds == ["paper"] * 4


def test_arrays_and_gap_table_are_read_only() -> None:
    m = load_vehicle("paper").compiled
    arrays = [f.name for f in fields(m) if isinstance(getattr(m, f.name), np.ndarray)]
    assert {"inertia", "ck", "chalf", "road", "speed_ratio", "cb2"} <= set(arrays)
    for name in arrays:
        with pytest.raises(ValueError, match="read-only"):
            getattr(m, name)[0] = 1
    with pytest.raises(TypeError):
        m.gap_coupling["halfshaft"] = 0  # type: ignore[index]


def test_equality_pickling_and_copies_ignore_it() -> None:
    v = load_vehicle("paper")
    m = v.compiled
    assert v == load_vehicle("paper")  # fields only
    back = pickle.loads(pickle.dumps(v))
    assert back == v and "compiled" not in back.__dict__
    assert _same(back.compiled, m)
    assert copy.deepcopy(v) == v and _same(copy.copy(v).compiled, m)


SPEED_ONLY_EFFECTS = {"drag": {"coulomb_nm": 4.0, "viscous_nms": 0.01},
                      "progressive_stiffness": {"halfshaft_rel": 0.5, "mount_rel": 0.5},
                      "tyre_slip": {"compliance_per_mn": 40.0, "relaxation_m": 0.3},
                      "torque_lag": {"delay_s": 0.004, "tau_s": 0.003},
                      "speed_sensor": {"tau_s": 0.002, "delay_s": 0.003}}


@pytest.mark.parametrize("which", ["paper", "paper_effects", "chain_drive", "chain_full", "single_reduction",
                                   "unequal"])
def test_speed_only_loop_gives_the_tracked_loop_s_rows_bit_for_bit(which: str) -> None:
    """Without state rows or gap events the kernel keeps no coupling torques or gap states (the serial chain's
    speed-only loop): the resolver, sensor and torque rows are those of the run that keeps them all."""
    if which == "unequal":
        v = unequal_chain_drive()
    elif which == "paper_effects":
        v = apply_effects(load_vehicle("paper"), SPEED_ONLY_EFFECTS)
    elif which == "chain_full":  # the dampers engaging in full (contact_damping)
        v = load_vehicle("chain_drive").with_changes({"contact_damping": "full"})
    else:
        v = load_vehicle(which)
    m = v.compiled
    t = np.arange(0.0, 3.0, 0.01)
    q = np.where(t < 1.0, -30.0, 90.0) + 5.0 * np.sin(7.0 * t)
    theta0, omega0, tyre0 = quasi_static_full(m, float(q[0]), 150.0)
    step, sub = choose_step(m, 1e-3, torque_max=90.0)
    eff = v.effects
    kw = {"lag": (eff.torque_lag.delay_s, eff.torque_lag.tau_s), "sensor_tau": eff.speed_sensor.tau_s}
    runs = [run_from_state(m, t, q, True, 0.0, step, sub, 2901, theta0, omega0, tyre0, events=ev, states=st, **kw)
            for ev, st in ((True, True), (True, False), (False, False))]
    full = runs[0]
    assert full.events and any(full.is_open[:, j].any() and not full.is_open[:, j].all() for j in range(m.n_couplings))
    for run in runs[1:]:
        for name in ("resolver", "sensor", "torque"):
            assert np.array_equal(getattr(run, name), getattr(full, name)), name
    assert runs[2].events == [] and runs[2].omega.shape[0] == 0
