"""The paper's two-inertia model (eqs. 1-6) against hand-derived results."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sim import load_vehicle, simulate
from sim.two_inertia import TwoInertiaParams, pack, project, run_two_inertia


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
