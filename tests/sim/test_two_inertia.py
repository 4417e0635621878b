"""The paper's two-inertia model (eqs. 1-6) against hand-derived results."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import load_vehicle, simulate
from sim.linear import state_matrix
from sim.model import build_chain
from sim.two_inertia import TwoInertiaParams, pack, project, run_two_inertia, series_impedance


def _run(p: TwoInertiaParams, torque: float, state0: list[float], t_end: float, dt: float = 1e-5,
         ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    arr, road = pack(p)
    n_out = round(t_end / 1e-4) + 1
    sub = round(1e-4 / dt)
    out = np.zeros((n_out, 5))
    ev_t = np.zeros(100)
    ev_k = np.zeros(100, dtype=np.int64)
    status, _, n_ev = run_two_inertia(arr, road, np.array([0.0, 10.0]), np.array([torque, torque]), False,
                                      0.0, dt, n_out, sub, np.array(state0), 1e6, out, ev_t, ev_k)
    assert status == 0
    return out, ev_t[:n_ev], ev_k[:n_ev], n_ev


BASE = TwoInertiaParams(jm=0.05, bm=0.0, ratio=10.0, khs=8000.0, chs=20.0, alpha=0.02, jw=60.0, n_shafts=2)


def test_gap_traverse_time_under_constant_torque() -> None:
    """At rest on the -alpha flank, unloaded: the motor runs free, th_m = T t^2 / (2 Jm), until
    it has turned 2 alpha i: t_close = sqrt(4 alpha i Jm / T)."""
    torque = 20.0
    p = BASE
    out, ev_t, ev_k, _n = _run(p, torque, [-p.alpha * p.ratio, 0.0, 0.0, 0.0, -p.alpha], 0.2)
    t_close = math.sqrt(4 * p.alpha * p.ratio * p.jm / torque)
    closes = ev_t[ev_k == 0]
    assert closes.size >= 1
    assert closes[0] == pytest.approx(t_close, abs=2e-5)
    # while open the shaft carries exactly zero torque and the motor accelerates at T/Jm
    k = int(0.5 * t_close / 1e-4)
    assert out[k, 2] == 0.0
    assert out[k, 0] == pytest.approx(torque / p.jm * k * 1e-4, rel=1e-3)


def test_steady_acceleration_torque_split_without_lash() -> None:
    """No lash, constant torque: uniform acceleration a = T / (Jm + n Jw / i^2); each shaft
    carries Jw a / i."""
    p = TwoInertiaParams(jm=0.05, bm=0.0, ratio=10.0, khs=8000.0, chs=200.0, alpha=0.0, jw=60.0, n_shafts=2)
    torque = 100.0
    out, *_ = _run(p, torque, [0.0, 0.0, 0.0, 0.0, 0.0], 1.5)
    a = torque / (p.jm + p.n_shafts * p.jw / p.ratio**2)
    assert out[-1, 2] == pytest.approx(p.jw * a / p.ratio, rel=2e-3)
    assert (out[-1, 0] - out[-11, 0]) / 1e-3 == pytest.approx(a, rel=2e-3)


def test_natural_frequency_without_lash() -> None:
    """Undamped, no lash: omega^2 = khs (n / (i^2 Jm) + 1 / Jw)."""
    p = TwoInertiaParams(jm=0.05, bm=0.0, ratio=10.0, khs=8000.0, chs=1e-9, alpha=0.0, jw=60.0, n_shafts=2)
    out, *_ = _run(p, 0.0, [0.0, 1.0, 0.0, 0.0, 0.0], 1.0, dt=2e-6)
    w = out[:, 0] - out[:, 0].mean()
    s = np.signbit(w)
    crossings = np.flatnonzero(s[1:] != s[:-1])
    period = 2 * np.mean(np.diff(crossings)) * 1e-4
    f_expected = math.sqrt(p.khs * (p.n_shafts / (p.ratio**2 * p.jm) + 1 / p.jw)) / (2 * math.pi)
    assert 1 / period == pytest.approx(f_expected, rel=5e-3)


def test_projection_of_paper_vehicle_and_simulate() -> None:
    v = load_vehicle("paper")
    p = project(v)
    assert p.ratio == pytest.approx(v.ratio)
    assert p.alpha == pytest.approx(sum(v.motor_side_gaps) / v.ratio / 2)
    assert p.khs < v.halfshaft.stiffness  # series compliance only softens
    t = np.arange(0.0, 0.5, 0.01)
    q = np.interp(t, [0.0, 0.1, 0.235, 1.0], [-50.0, -50.0, 150.0, 150.0])
    res = simulate(v, t, q, model="two_inertia", interp="linear")
    assert res.gap_events and res.gap_events[0][0] == "lumped"
    t_open, t_close = res.gap_events[0][1], res.gap_events[0][2]
    assert 0.1 < t_open < t_close < 0.25
    assert np.all(res.coupling_torques["halfshaft"][res.gap_open["lumped"]] == 0.0)


def _multibody_first_mode(v) -> tuple[float, float]:  # type: ignore[no-untyped-def]
    """(Hz, damping ratio) of the lowest oscillatory eigenvalue of the linearised chain, gaps closed."""
    lam = np.linalg.eigvals(state_matrix(build_chain(v)))
    lam = lam[(np.abs(lam) > 1e-3) & (lam.imag > 0)]
    z = lam[np.argmin(np.abs(lam))]
    return abs(z) / (2 * math.pi), -z.real / abs(z)


def _two_inertia_mode(p: TwoInertiaParams) -> tuple[float, float]:
    """Hand-derived: relative coordinate, k = n khs and c = n chs in wheel angle between Jm i^2 and n Jw."""
    inv = 1.0 / (p.ratio**2 * p.jm) + 1.0 / (p.n_shafts * p.jw)
    wn = math.sqrt(p.n_shafts * p.khs * inv)
    return wn / (2 * math.pi), p.n_shafts * p.chs * inv / (2 * wn)


@pytest.mark.parametrize("name, changes", [("paper", {}), ("paper", {"housing.enabled": False}),
                                           ("paper", {"halfshaft.damping": 5.0, "reducer.spline_damping": 0.05}),
                                           ("single_reduction", {}), ("chain_drive", {})])
def test_projection_first_mode_matches_multibody(name: str, changes: dict[str, object]) -> None:
    """Series spring-damper pairs (complex impedances) keep the multibody's first mode: frequency and
    damping ratio within 5 %. The earlier 1/c = sum 1/c_i reduction gave 0.005 instead of 0.064 on
    the paper preset, because the stiff, lightly damped spline set the damping of the whole chain."""
    v = load_vehicle(name).with_changes(changes)
    f_mb, z_mb = _multibody_first_mode(v)
    f_ti, z_ti = _two_inertia_mode(project(v))
    assert f_ti == pytest.approx(f_mb, rel=0.05)
    assert z_ti == pytest.approx(z_mb, rel=0.05)
    assert z_mb > 0.01  # a real test of damping, not of two tiny numbers


def test_projected_two_inertia_rings_down_like_the_multibody_mode() -> None:
    """The simulated two-inertia ring-down (no lash, kicked rotor) has the multibody first mode's
    frequency and logarithmic decrement within 5 %."""
    v = load_vehicle("paper")
    f_mb, z_mb = _multibody_first_mode(v)
    p = project(v)
    p = TwoInertiaParams(**{**p.__dict__, "alpha": 0.0, "road": (0.32, 0.0, 0.0, 0.0, 0.0, 0.0)})
    out, *_ = _run(p, 0.0, [0.0, 10.0, 0.0, 0.0, 0.0], 0.8, dt=2e-6)
    w_rel = out[:, 0] / p.ratio - out[:, 1]  # relative speed: the mode alone, no rigid-body drift
    peaks = [k for k in range(1, w_rel.size - 1) if w_rel[k - 1] < w_rel[k] >= w_rel[k + 1] and w_rel[k] > 0]
    assert len(peaks) >= 4
    period = float(np.mean(np.diff(peaks))) * 1e-4
    delta = math.log(w_rel[peaks[0]] / w_rel[peaks[3]]) / 3
    zeta = delta / math.sqrt(4 * math.pi**2 + delta**2)
    f_damped_mb = f_mb * math.sqrt(1 - z_mb**2)
    assert 1 / period == pytest.approx(f_damped_mb, rel=0.05)
    assert zeta == pytest.approx(z_mb, rel=0.05)


def test_series_impedance_by_hand() -> None:
    """Two pairs: k = Re Z and c = Im Z / omega of 1 / (1/(k1 + i w c1) + 1/(k2 + i w c2)) at
    the mode w^2 = k / J; undamped pairs give the plain series spring."""
    k, c = np.array([1.0e4, 4.0e4]), np.array([20.0, 5.0])
    ke, ce, w = series_impedance(k, c, 1.0 / 2.0)
    z = 1.0 / (1.0 / (k[0] + 1j * w * c[0]) + 1.0 / (k[1] + 1j * w * c[1]))
    assert (ke, ce) == pytest.approx((z.real, z.imag / w), rel=1e-9)
    assert w == pytest.approx(math.sqrt(ke / 2.0), rel=1e-9)
    assert ce > 1.0 / (1.0 / c[0] + 1.0 / c[1])  # far more than the dampers "in series" alone (4 N m s/rad)
    k0, c0, _ = series_impedance(k, np.zeros(2), 0.5)
    assert k0 == pytest.approx(8000.0, rel=1e-12) and c0 == 0.0
