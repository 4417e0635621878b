"""The compiled chain belongs to the Vehicle: built once per object, read-only, shared by every run of it."""

from __future__ import annotations

import copy
import pickle
from dataclasses import fields

import numpy as np
import pytest

from sim import WhatIf, load_vehicle, simulate
from sim.batch import simulate_batch
from sim.model import build_chain
from sim.paper import tip_in_torque
from sim.simulate import simulate_speed


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
