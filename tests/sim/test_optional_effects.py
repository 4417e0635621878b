"""Progressive stiffness and tyre slip: off changes nothing, on matches its linearisation and energy."""

from __future__ import annotations

import numpy as np
import pytest

from sim import load_vehicle, simulate
from sim.batch import simulate_batch
from sim.linear import max_rate, state_matrix
from sim.model import build_chain, deflections, quasi_static_full, spring_deflection
from sim.paper import tip_in_torque
from sim.runner import run_from_state
from sim.simulate import RPM, choose_step

PAPER = load_vehicle("paper")
GAPS = ("spline", "mesh1", "mesh2", "differential", "halfshaft")
NO_ROAD = {"body.rolling_resistance": 0.0, "body.drag_area": 0.0}
PROGRESSIVE = {"effects.progressive_stiffness.halfshaft": 1.0e5, "effects.progressive_stiffness.mesh2": 5.0e9,
               "effects.progressive_stiffness.spline": 1.0e7, "effects.progressive_stiffness.mount": 1.0e8}


def test_off_is_bit_for_bit_the_classic_model() -> None:
    t, q = tip_in_torque(duration_s=0.4)
    off = PAPER.with_changes({**{k: 0.0 for k in PROGRESSIVE}, "effects.tyre_slip.enabled": False,
                              "effects.tyre_slip.slip_stiffness": 1.0e5, "effects.tyre_slip.relaxation_length": 0.3})
    assert off != PAPER
    a, b = simulate(PAPER, t, q, interp="linear"), simulate(off, t, q, interp="linear")
    assert np.array_equal(a.motor_speed_rpm, b.motor_speed_rpm) and a.gap_events == b.gap_events
    assert all(np.array_equal(a.coupling_torques[k], b.coupling_torques[k]) for k in a.coupling_torques)
    assert np.array_equal(a.vehicle_speed_kmh, b.vehicle_speed_kmh) and "tyre" not in a.coupling_torques
    batch = simulate_batch(PAPER, [{}, {k: 0.0 for k in PROGRESSIVE}], t, q, interp="linear")
    assert np.array_equal(batch.motor_speed_rpm[0], batch.motor_speed_rpm[1])
    # the two-inertia projection ignores both effects
    on = PAPER.with_changes({**PROGRESSIVE, "effects.tyre_slip.enabled": True})
    assert np.array_equal(simulate(on, t, q, model="two_inertia").motor_speed_rpm,
                          simulate(PAPER, t, q, model="two_inertia").motor_speed_rpm)


def _mode_response(v, torque: float, speed_rpm: float, mode_hz: float, tangent: bool):  # type: ignore[no-untyped-def]
    """Simulated and predicted deviation of the resolver speed after a small push along one mode.

    The chain runs quasi-statically at ``torque`` (gaps zero, no road load: uniform acceleration
    is then an exact solution); the pushed run minus the unpushed run is compared with
    ``Re(v exp(lambda t))`` of the state matrix linearised there (tangent stiffness of the
    progressive springs at their static deflection, tyre relaxation at the vehicle speed).
    """
    m = build_chain(v)
    theta, omega, tyre0 = quasi_static_full(m, torque, speed_rpm / RPM)
    x0 = np.abs(deflections(m, theta))
    ck = m.ck + 3.0 * m.ck3 * x0**2 if tangent else m.ck
    w_v = float(omega[m.vehicle]) if m.vehicle >= 0 else 0.0
    lam, vec = np.linalg.eig(state_matrix(m, w_v, ck))
    k = int(np.argmin(np.abs(lam - 1j * 2 * np.pi * mode_hz)))
    nb = m.n_bodies
    shape = vec[:, k] / vec[nb + m.rotor, k] * (5.0 / RPM)  # 5 rpm of rotor speed
    step, sub = choose_step(m, 1e-3, 0.3 * 2 / max_rate(m, w_v, ck))
    n = 400
    q_in = np.array([torque, torque])
    t_in = np.array([0.0, 10.0])
    base = run_from_state(m, t_in, q_in, False, 0.0, step, sub, n, theta, omega, tyre0)
    extra = shape.real
    tyre_push = float(extra[-1]) if m.vehicle >= 0 else 0.0
    pushed = run_from_state(m, t_in, q_in, False, 0.0, step, sub, n, theta + extra[:nb], omega + extra[nb:2 * nb],
                            tyre0 + tyre_push)
    t = np.arange(n) * 1e-3
    predicted = (np.exp(np.outer(t, [lam[k]])) * shape[[nb + m.rotor, nb + m.housing]]).real
    return (pushed.resolver - base.resolver) * RPM, (predicted[:, 0] - predicted[:, 1]) * RPM, lam[k], base


@pytest.mark.parametrize("changes", [PROGRESSIVE, {"effects.tyre_slip.enabled": True}], ids=["cubic", "tyre"])
def test_response_equals_the_linearisation(changes: dict[str, object]) -> None:
    """A small shuffle-mode oscillation on top of the operating point follows ``Re(v e^(lambda t))``."""
    v = PAPER.with_changes({**changes, **NO_ROAD, **{f"gaps.{g}": 0.0 for g in GAPS}})
    sim, pred, _, base = _mode_response(v, 150.0, 2000.0, 7.5, tangent=True)
    assert np.abs(sim - pred).max() < 0.03 * np.abs(pred).max()
    assert np.abs(pred[-100:]).max() < 0.5 * np.abs(pred[:100]).max()  # a damped oscillation, not a constant
    # the unpushed run stays on the operating point: no start-up transient (with the tyre, the slip
    # speed of a constant force grows with the vehicle speed, a slow drift of a few 1e-4 over 0.4 s)
    rtol = 2e-3 if "effects.tyre_slip.enabled" in changes else 1e-6
    assert np.allclose(base.tau[:, :6], base.tau[0, :6], rtol=rtol, atol=1e-6)
    assert np.allclose(base.tyre, base.tyre[0], rtol=rtol, atol=1e-6)


def _damped(lam: complex) -> tuple[float, float]:
    return abs(lam.imag) / (2 * np.pi), -lam.real / abs(lam)


def test_directions_of_the_shuffle_mode() -> None:
    """Hardening raises the loaded shuffle frequency; tyre compliance lowers it and adds damping."""
    gaps0 = {**NO_ROAD, **{f"gaps.{g}": 0.0 for g in GAPS}}
    _, _, lin, _ = _mode_response(PAPER.with_changes(gaps0), 150.0, 2000.0, 7.5, tangent=True)
    _, _, hard, _ = _mode_response(PAPER.with_changes({**gaps0, **PROGRESSIVE}), 150.0, 2000.0, 7.5, tangent=True)
    sim_off, _, _, _ = _mode_response(PAPER.with_changes(gaps0), 0.0, 2000.0, 7.5, tangent=False)
    sim_on, _, tyre, _ = _mode_response(PAPER.with_changes({**gaps0, "effects.tyre_slip.enabled": True}),
                                        0.0, 2000.0, 7.5, tangent=False)
    f_lin, z_lin = _damped(lin)
    f_hard, _ = _damped(hard)
    f_tyre, z_tyre = _damped(tyre)
    assert f_hard > 1.05 * f_lin
    assert f_tyre < 0.97 * f_lin and z_tyre > 1.3 * z_lin
    # and in the simulated signals themselves: a lower frequency, a faster decay
    def frequency_and_decay(y: np.ndarray) -> tuple[float, float]:
        s = np.signbit(y)
        cross = np.flatnonzero(s[1:] != s[:-1]) * 1e-3  # zero crossings, 1 ms grid
        freq = (cross.size - 1) / (2 * (cross[-1] - cross[0]))
        return freq, float(np.abs(y[300:]).max() / np.abs(y[:100]).max())
    f_off, d_off = frequency_and_decay(sim_off)
    f_on, d_on = frequency_and_decay(sim_on)
    assert f_off == pytest.approx(f_lin, rel=0.03) and f_on == pytest.approx(f_tyre, rel=0.03)
    assert f_on < 0.97 * f_off and d_on < 0.8 * d_off


@pytest.mark.parametrize("tyre", [False, True])
def test_energy_balance_without_damping(tyre: bool) -> None:
    """No damping, no road: kinetic + elastic (incl. k3 x^4 / 4 and the tyre spring) energy is conserved,
    except what the tyre's relaxation dissipates, which is integrated alongside."""
    changes: dict[str, object] = {**NO_ROAD, **PROGRESSIVE, "effects.tyre_slip.enabled": tyre}
    for f in ("spline_damping", "mesh1_damping", "mesh2_damping", "diff_damping"):
        changes[f"reducer.{f}"] = 0.0
    changes.update({"halfshaft.damping": 0.0, "housing.mount_damping": 0.0})
    v = PAPER.with_changes(changes)
    m = build_chain(v)
    theta, omega, tyre0 = quasi_static_full(m, 150.0, 0.0)
    omega = omega + 200.0 * m.speed_ratio  # wound up, rolling at ~2000 rpm, then released
    out_dt = 2e-4
    step, sub = choose_step(m, out_dt, 0.03 * 2 / max_rate(m))
    run = run_from_state(m, np.array([0.0, 10.0]), np.zeros(2), False, 0.0, step, sub, 2001, theta, omega, tyre0)
    x = spring_deflection(m.ck, m.ck3, run.tau)
    elastic = (0.5 * m.ck * x**2 + 0.25 * m.ck3 * x**4).sum(axis=1)
    kinetic = 0.5 * (run.omega**2 * m.inertia).sum(axis=1)
    e = kinetic + elastic
    if tyre:
        e = e + 0.5 * run.tyre**2 / m.tyre[0]
    wound = e[0] - kinetic[0]  # the oscillation energy: the rigid roll's kinetic energy is far larger
    if tyre:
        power = m.tyre[1] * np.abs(run.omega[:, m.vehicle]) * run.tyre**2 / m.tyre[0]
        lost = np.concatenate(([0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * out_dt)))
        assert lost[-1] > 0.05 * wound  # the tyre really dissipates
        e = e + lost
    assert (0.25 * m.ck3 * x**4).sum(axis=1).max() > 0.01 * wound  # the cubic terms really work
    assert np.abs(e - e[0]).max() < 0.01 * wound


def test_tyre_slip_outputs_and_quasi_static_start() -> None:
    v = PAPER.with_changes({"effects.tyre_slip.enabled": True, **PROGRESSIVE})
    t = np.arange(0.0, 0.3, 0.01)
    res = simulate(v, t, np.full(t.size, 120.0))
    assert res.gap_events == []
    tyre = res.coupling_torques["tyre"]
    assert np.abs(tyre - tyre[0]).max() < 0.01 * abs(tyre[0])
    assert tyre[0] == pytest.approx(res.coupling_torques["halfshaft1"][0] * 2, rel=0.02)  # both shafts feed the tyres
    slip = res.wheel_speed_rpm / (res.vehicle_speed_kmh / 3.6 / v.wheel.radius * RPM) - 1.0
    force = tyre[0] / v.wheel.radius / 2  # per tyre
    assert slip[5] == pytest.approx(force / v.effects.tyre_slip.slip_stiffness, rel=0.02)


def test_batch_with_tyre_and_cubic_equals_single_runs() -> None:
    v = PAPER.with_changes({"effects.tyre_slip.enabled": True, **PROGRESSIVE})
    t, q = tip_in_torque(duration_s=0.3)
    variants = [{}, {"effects.tyre_slip.relaxation_length": 0.3, "effects.progressive_stiffness.halfshaft": 0.0}]
    batch = simulate_batch(v, variants, t, q, interp="linear")
    for k, change in enumerate(variants):
        single = simulate(v.with_changes(change), t, q, interp="linear")
        assert np.allclose(batch.motor_speed_rpm[k], single.motor_speed_rpm, atol=1e-9)
        assert batch.gap_events[k] == single.gap_events
    assert not np.allclose(batch.motor_speed_rpm[0], batch.motor_speed_rpm[1])
