"""Implicit dampers: the kernel's linearly implicit kick for heavily damped couplings between light bodies."""

from __future__ import annotations

import importlib

import numpy as np
import pytest

from sim import InstabilityError, load_vehicle
from sim.linear import damper_rates, step_limit, tangent_stiffness
from sim.metrics import peak_to_valley
from sim.model import build_chain, quasi_static_full
from sim.paper import tip_in_torque
from sim.reference import solve_reference
from sim.runner import run_from_state
from sim.simulate import RPM, plan_step, simulate
from tests.sim.test_topologies import unequal_chain_drive

simulate_module = importlib.import_module("sim.simulate")  # the module (sim.simulate is also the function)
PAPER = load_vehicle("paper")


def _damped(factor: float, v=PAPER):  # type: ignore[no-untyped-def]
    """Every stage's damping times ``factor``, in the file's own layout."""
    fields = [v.field_of(s.name, "damping") for s in v.chain
              if s.kind not in ("rotor", "wheel") and s.has_coupling and float(s.damping) > 0.0]
    return v.with_changes({f: float(v.get(f)) * factor for f in fields})


@pytest.fixture
def auto_implicit(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(simulate_module, "AUTO_IMPLICIT", True)


def test_damper_rates_and_lifted_limit() -> None:
    """A damper's rate is ``c g' J^-1 g``; leaving the stiff ones out of the limit lifts it, never lowers it."""
    m = build_chain(_damped(8.0))
    rates = damper_rates(m)
    j = m.n_couplings - 2  # the half-shaft: body nc-2 to the wheel, no housing term
    assert rates[j] == pytest.approx(m.cc[j] * (1 / m.inertia[m.ca[j]] + m.cr[j] ** 2 / m.inertia[m.cb[j]]))
    ck = tangent_stiffness(m, 200.0)
    explicit = step_limit(m, 0.0, ck)
    every = np.ones(m.n_couplings, dtype=np.bool_)
    assert step_limit(m, 0.0, ck, every) > 5.0 * explicit  # the damping, not a stiffness, set the limit
    assert step_limit(m, 0.0, ck, np.zeros(m.n_couplings, dtype=np.bool_)) == pytest.approx(explicit)


def test_plan_keeps_the_explicit_kick_unless_asked_and_where_it_does_not_pay(auto_implicit: None) -> None:
    _, sub, mask = plan_step(build_chain(PAPER), 1e-3, torque_max=200.0)
    assert not mask.any() and sub == 15  # the paper car: a stiffness sets the step
    _, sub, mask = plan_step(build_chain(_damped(8.0)), 1e-3, torque_max=200.0)
    assert mask.any() and sub <= 16
    assert not plan_step(build_chain(_damped(8.0)), 1e-3, 1e-5)[2].any()  # a given step stays explicit


def test_default_is_the_explicit_kick() -> None:
    assert simulate_module.AUTO_IMPLICIT is False
    assert not plan_step(build_chain(_damped(8.0)), 1e-3, torque_max=200.0)[2].any()


@pytest.mark.parametrize("factor", [3.0, 8.0])
def test_implicit_dampers_against_tight_reference(factor: float, auto_implicit: None) -> None:
    """Dampers x3 and x8: the implicit kick at the lifted step tracks LSODA (rtol 1e-8) as closely as the explicit
    kick at its own, 2.5-7x shorter step: speed within 0.2 rpm RMS and the shuffle's peak-valley within 1 rpm."""
    v = _damped(factor)
    t, q = tip_in_torque(1.0, duration_s=0.45)
    res = simulate(v, t, q, interp="linear")
    m = build_chain(v)
    _, _, mask = plan_step(m, 1e-3, torque_max=float(np.max(np.abs(q))))
    assert mask.any()
    explicit_dt = simulate_module.STEP_SAFETY * step_limit(m, 0.0, tangent_stiffness(m, float(np.max(np.abs(q)))))
    assert res.dt > 2.4 * explicit_dt
    fine = np.arange(0.0, 0.45, 2e-5)
    _, omega, _ = solve_reference(m, t, q, True, res.rotor_speed_rpm[0] / RPM, fine, rtol=1e-8, atol=1e-9)
    ref = np.interp(res.t, fine, (omega[:, m.rotor] - omega[:, m.housing]) * RPM)
    err = res.motor_speed_rpm - ref
    assert float(np.sqrt(np.mean(err ** 2))) < 0.2
    ours, theirs = peak_to_valley(res.t, res.motor_speed_rpm, 0.05, 0.4), peak_to_valley(res.t, ref, 0.05, 0.4)
    assert ours > 100.0 and ours == pytest.approx(theirs, abs=1.0)


def test_the_lifted_step_is_beyond_the_explicit_kick() -> None:
    """At the step the implicit dampers allow the explicit kick is far off on the same chain, and at twice that
    step (0.8 of the lifted limit) it diverges while the implicit kick still runs."""
    m = build_chain(_damped(8.0))
    t, q = tip_in_torque(1.0, duration_s=0.3)
    theta0, omega0, tyre0 = quasi_static_full(m, float(q[0]), 100.0)
    every = np.ones(m.n_couplings, dtype=np.bool_)
    stiff = damper_rates(m) * step_limit(m, 0.0, None, every) > simulate_module.STIFF_DAMPER
    lifted = step_limit(m, 0.0, None, stiff)
    runs = {}
    for safety in (simulate_module.STEP_SAFETY, 0.8):
        sub = int(np.ceil(1e-3 / (safety * lifted)))
        imp = run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 301, theta0, omega0, tyre0, implicit=stiff)
        assert np.all(np.isfinite(imp.resolver)) and np.ptp(imp.resolver * RPM) > 300.0
        runs[safety] = (sub, imp.resolver)
    sub, imp = runs[simulate_module.STEP_SAFETY]
    exp = run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 301, theta0, omega0, tyre0, speed_limit=1e4)
    assert float(np.max(np.abs(exp.resolver - imp))) * RPM > 20.0
    sub, _ = runs[0.8]
    with pytest.raises(InstabilityError):
        run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 301, theta0, omega0, tyre0, speed_limit=1e4)


@pytest.mark.parametrize("which", ["paper", "unequal"])
def test_implicit_loops_agree_and_none_set_is_explicit(which: str) -> None:
    """The kernel's three loops (speed only, serial with states, any chain) give the same speeds with implicit
    dampers; with none set the run is the explicit one bit for bit."""
    v = _damped(6.0, PAPER if which == "paper" else unequal_chain_drive())
    m = v.compiled
    t = np.arange(0.0, 2.0, 0.01)
    q = np.where(t < 0.7, -30.0, 90.0) + 5.0 * np.sin(7.0 * t)
    theta0, omega0, tyre0 = quasi_static_full(m, float(q[0]), 150.0)
    every = np.ones(m.n_couplings, dtype=np.bool_)
    step = simulate_module.STEP_SAFETY * step_limit(m, 0.0, tangent_stiffness(m, 90.0), every)
    sub = int(np.ceil(1e-3 / step))
    runs = [run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 1901, theta0, omega0, tyre0, events=ev, states=st,
                           implicit=every) for ev, st in ((True, True), (False, False))]
    assert np.array_equal(runs[0].resolver, runs[1].resolver)
    assert np.all(np.isfinite(runs[0].resolver)) and np.ptp(runs[0].resolver) > 1.0
    small = simulate_module.STEP_SAFETY * step_limit(m, 0.0, tangent_stiffness(m, 90.0))
    sub = int(np.ceil(1e-3 / small))
    plain = run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 1901, theta0, omega0, tyre0)
    none = run_from_state(m, t, q, True, 0.0, 1e-3 / sub, sub, 1901, theta0, omega0, tyre0,
                          implicit=np.zeros(m.n_couplings, dtype=np.bool_))
    assert np.array_equal(plain.resolver, none.resolver)
    # the implicit run at its long step and the explicit one at its short step tell the same story
    assert float(np.max(np.abs(runs[0].resolver - plain.resolver))) * RPM < 2.0
