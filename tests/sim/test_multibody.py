"""Multibody chain: accuracy against solve_ivp, energy, linear limit, modes, initial state, errors."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from sim import InputSignalError, InstabilityError, load_vehicle, simulate
from sim.linear import linear_matrices, modal_frequencies_hz
from sim.metrics import peak_to_valley, unloaded_time
from sim.model import build_chain, deflections
from sim.paper import tip_in_torque
from sim.reference import coupling_matrix, solve_reference
from sim.runner import run_from_state
from sim.simulate import RPM, choose_step

PAPER = load_vehicle("paper")


@pytest.mark.parametrize("scale", [1.0, 0.5])
def test_against_tight_solve_ivp_reference(scale: float) -> None:
    """p2p ripple within 1 rpm and unloaded (gap-open) time within 0.2 ms of LSODA at rtol 1e-8."""
    t, q = tip_in_torque(scale, duration_s=0.45)
    res = simulate(PAPER, t, q, interp="linear")
    m = build_chain(PAPER)
    fine = np.arange(0.0, 0.45, 2e-5)
    theta, omega, _ = solve_reference(m, t, q, True, res.rotor_speed_rpm[0] / RPM, fine, rtol=1e-8, atol=1e-9)
    ref_speed = (omega[:, m.rotor] - omega[:, m.housing]) * RPM
    delta = theta @ coupling_matrix(m).T
    open_any = np.any(np.abs(delta[:, :5]) < m.chalf[:5], axis=1)
    k0 = int(np.flatnonzero(open_any)[0])
    k1 = k0 + int(np.argmin(open_any[k0:]))
    ref_unloaded = fine[k1] - fine[k0]
    ours_unloaded = unloaded_time(res.gap_events, 0.05)
    assert ours_unloaded == pytest.approx(ref_unloaded, abs=2e-4)
    w = (fine[k0] - 0.005, fine[k0] + 0.3)
    ours = peak_to_valley(res.t, res.motor_speed_rpm, *w)
    ref = peak_to_valley(res.t, np.interp(res.t, fine, ref_speed), *w)
    assert ours > 100.0  # a real shuffle, not a flat line
    assert ours == pytest.approx(ref, abs=1.0)


def _free_vehicle(gap_scale: float = 0.0, damping: float = 0.0):  # type: ignore[no-untyped-def]
    """The paper vehicle without road load and with damping scaled (0 = conservative)."""
    v = PAPER
    changes: dict[str, object] = {f"gaps.{g}": getattr(v.gaps, g).nominal * gap_scale
                                  for g in ("spline", "mesh1", "mesh2", "differential", "halfshaft")}
    for f in ("spline_damping", "mesh1_damping", "mesh2_damping", "diff_damping"):
        changes[f"reducer.{f}"] = getattr(v.reducer, f) * damping
    changes.update({"halfshaft.damping": v.halfshaft.damping * damping,
                    "housing.mount_damping": v.housing.mount_damping * damping,
                    "body.rolling_resistance": 0.0, "body.drag_area": 0.0})
    return v.with_changes(changes)


def _run_raw(v, theta0, omega0, torque: float, t_end: float, dt: float | None = None):  # type: ignore[no-untyped-def]
    m = build_chain(v)
    step, sub = choose_step(m, 1e-3, dt)
    n_out = round(t_end / 1e-3) + 1
    run = run_from_state(m, np.array([0.0, 100.0]), np.array([torque, torque]), False, 0.0, step, sub, n_out,
                         theta0, omega0)
    return m, run.omega, run.tau


@pytest.mark.parametrize("gap_scale", [0.0, 1.0])
def test_energy_conserved_without_damping(gap_scale: float) -> None:
    """No damping, no road: released from a wound-up state, kinetic + elastic energy stays constant.

    With lash the gaps open and slam shut on the way; the elastic backlash without damping
    is still conservative. A tenth of the usual step keeps the symplectic scheme's bounded
    energy oscillation (order omega*dt) small.
    """
    from sim.linear import max_rate
    from sim.model import quasi_static_state

    v = _free_vehicle(gap_scale)
    m = build_chain(v)
    theta0, omega0 = quasi_static_state(m, 150.0, 0.0)
    omega0 = omega0 + 3.0 * m.speed_ratio  # a rigid roll on top
    m, om, tau = _run_raw(v, theta0, omega0, 0.0, 0.5, dt=0.03 * 2 / max_rate(m))
    kinetic = 0.5 * (om**2 * m.inertia).sum(axis=1)
    elastic = (tau**2 / (2 * m.ck)).sum(axis=1)  # tau = k x on every engaged coupling
    e = kinetic + elastic
    assert elastic[0] > 0.1 * e[0]
    assert np.abs(e - e[0]).max() / e[0] < 0.01


def test_zero_lash_equals_linear_model() -> None:
    """Gaps at zero: the response to a torque step equals the exact linear solution (matrix exponential)."""
    v = _free_vehicle(0.0, damping=1.0)
    m = build_chain(v)
    M, K, C = linear_matrices(m)
    nb = m.n_bodies
    Minv = np.diag(1 / np.diag(M))
    A = np.block([[np.zeros((nb, nb)), np.eye(nb)], [-Minv @ K, -Minv @ C]])
    b = np.zeros(2 * nb)
    b[nb + m.rotor] = 1 / m.inertia[m.rotor]
    b[nb + m.housing] = -1 / m.inertia[m.housing]
    torque = 80.0
    _, om, _ = _run_raw(v, np.zeros(nb), np.zeros(nb), torque, 0.2)
    aug = np.zeros((2 * nb + 1, 2 * nb + 1))
    aug[: 2 * nb, : 2 * nb] = A
    aug[: 2 * nb, -1] = b * torque
    for k in (20, 57, 133, 200):
        x = expm(aug * k * 1e-3)[: 2 * nb, -1]
        resolver = (x[nb + m.rotor] - x[nb + m.housing]) * RPM
        ours = (om[k, m.rotor] - om[k, m.housing]) * RPM
        assert ours == pytest.approx(resolver, abs=0.5)
    # a vanishing lash converges to the same response
    _, om_tiny, _ = _run_raw(_free_vehicle(1e-6, 1.0), np.zeros(nb), np.zeros(nb), torque, 0.2)
    assert np.abs(om_tiny[:, 0] - om[:, 0]).max() * RPM < 1.0


def test_modal_frequencies_match_eigenvalues() -> None:
    """Started in one undamped mode shape, the chain oscillates at that eigenfrequency."""
    v = _free_vehicle(0.0)
    m = build_chain(v)
    M, K, _ = linear_matrices(m)
    lam, vec = np.linalg.eig(np.linalg.solve(M, K))
    order = np.argsort(lam.real)
    freqs = modal_frequencies_hz(m)
    for idx in order[1:4]:
        f = np.sqrt(lam[idx].real) / (2 * np.pi)
        assert f == pytest.approx(freqs[list(order).index(idx)], rel=1e-9)
        shape = vec[:, idx].real
        t_end = min(0.4, 8 / f)
        dt = 0.02 / f if f > 100 else None
        _, om, _ = _run_raw(v, shape * 1e-3 / np.abs(shape).max(), np.zeros(m.n_bodies), 0.0, t_end, dt)
        body = int(np.argmax(np.abs(shape)))
        theta = np.cumsum(om[:, body]) * 1e-3  # zero crossings of speed suffice
        s = np.signbit(om[1:, body])
        cross = np.flatnonzero(s[1:] != s[:-1])
        assert cross.size >= 4, f"{f:.1f} Hz mode: {cross.size} speed zero crossings in {t_end:.3f} s"
        period = 2 * np.mean(np.diff(cross)) * 1e-3
        assert 1 / period == pytest.approx(f, rel=0.02)
        assert np.isfinite(theta).all()


def test_quasi_static_start_has_no_transient() -> None:
    """Constant torque from t0: coupling torques stay at their initial values, gaps stay closed."""
    t = np.arange(0.0, 0.3, 0.01)
    res = simulate(PAPER, t, np.full(t.size, 120.0))
    for name in ("spline", "gear2", "halfshaft1"):
        tq = res.coupling_torques[name]
        assert np.abs(tq - tq[1]).max() < 0.01 * abs(tq[1]) + 0.5
    assert res.gap_events == []
    assert res.coupling_torques["gear2"][5] == pytest.approx(120.0 * PAPER.ratio, rel=0.05)
    # resolver reads rotor relative to housing
    rel = res.body_speeds_rpm["rotor"] - res.body_speeds_rpm["housing"]
    assert np.allclose(res.motor_speed_rpm, rel)


def test_tip_in_opens_and_closes_all_five_gaps() -> None:
    t, q = tip_in_torque(duration_s=0.4)
    res = simulate(PAPER, t, q, interp="linear")
    opened = {g for g, _, _ in res.gap_events}
    assert opened == {"spline", "mesh1", "mesh2", "differential", "halfshaft"}
    assert all(np.isfinite(c) for _, _, c in res.gap_events)
    assert all(np.all(res.coupling_torques[c][res.gap_open[g]] == 0.0)
               for g, c in (("mesh2", "gear2"), ("differential", "diff")))
    # housing roll shows in the resolver speed
    assert np.abs(res.motor_speed_rpm - res.rotor_speed_rpm).max() > 1.0


def test_hold_and_linear_differ_on_sparse_irregular_samples() -> None:
    t = np.concatenate(([0.0, 0.013, 0.02], np.arange(0.09, 0.25, 0.01)))  # irregular, with a 70 ms hole
    q = np.interp(t, [0.0, 0.013, 0.02, 0.09, 0.1, 1.0], [-40.0, -40.0, 0.0, 60.0, 100.0, 100.0])
    hold = simulate(PAPER, t, q, interp="hold")
    lin = simulate(PAPER, t, q, interp="linear")
    assert hold.input_gaps == ((0.02, 0.09),)
    k = int(np.searchsorted(hold.t, 0.05))
    assert hold.airgap_torque_nm[k] == 0.0
    assert lin.airgap_torque_nm[k] == pytest.approx(60 * 30 / 70, rel=0.01)  # torque over the last step
    assert not np.allclose(hold.motor_speed_rpm, lin.motor_speed_rpm)


def test_step_limit_is_the_stability_boundary() -> None:
    """The mode-by-mode limit of sim.linear.step_limit is where the scheme really turns unstable."""
    from sim.linear import step_limit

    lim = step_limit(build_chain(PAPER))
    t, q = tip_in_torque(duration_s=1.0)
    ok = simulate(PAPER, t, q, interp="linear", dt=0.95 * lim, output_dt=0.95 * lim)
    assert np.isfinite(ok.motor_speed_rpm).all() and np.ptp(ok.motor_speed_rpm) < 2000.0
    with pytest.raises(InstabilityError):
        simulate(PAPER, t, q, interp="linear", dt=1.1 * lim, output_dt=1.1 * lim)
    assert choose_step(build_chain(PAPER), 1e-3)[0] <= 0.4 * lim


def test_errors() -> None:
    t, q = tip_in_torque(duration_s=0.3)
    with pytest.raises(InstabilityError, match="dt"):
        simulate(PAPER, t, q, dt=5e-3, output_dt=5e-3)
    with pytest.raises(InputSignalError, match="strictly increase"):
        simulate(PAPER, [0.0, 0.2, 0.1], [1.0, 2.0, 3.0])
    with pytest.raises(InputSignalError, match="finite"):
        simulate(PAPER, [0.0, 0.1, 0.2], [1.0, np.nan, 3.0])
    with pytest.raises(InputSignalError):
        simulate(PAPER, [], [])


def test_deflections_match_kernel_initial_state() -> None:
    from sim.model import quasi_static_state

    m = build_chain(PAPER)
    theta, _ = quasi_static_state(m, 100.0, 200.0)
    d = deflections(m, theta)
    assert np.all(d[:5] > m.chalf[:5])  # closed on the drive flank
    theta, _ = quasi_static_state(m, -60.0, 200.0)
    assert np.all(deflections(m, theta)[:5] < -m.chalf[:5])
