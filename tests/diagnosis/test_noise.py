from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.noise import estimate_noise_floor
from app.analysis.diagnosis.uncertainty import torque_quantisation_variance
from app.analysis.series import quantisation_step


@pytest.mark.parametrize(("sigma", "q", "jitter"), [(0.5, 1.0, 0.0002), (1.5, 0.25, 0.0005), (0.3, 0.0, 0.0)])
def test_noise_floor_recovers_white_noise_quantisation_and_jitter(sigma: float, q: float, jitter: float) -> None:
    rng = np.random.default_rng(0)
    n = 6000
    t_valid = 0.01 * np.arange(n) + 0.0031
    t = t_valid + rng.normal(0.0, jitter, n) if jitter else t_valid
    keep = rng.random(n) > 0.01  # drop-outs
    slow = 2000 + 300 * np.sin(2 * np.pi * 0.05 * t_valid)  # a slow drive, no transients
    v = slow + rng.normal(0.0, sigma, n)
    if q:
        v = np.round(v / q) * q
    nf = estimate_noise_floor(t[keep], v[keep])
    expected = np.sqrt(sigma**2 + q**2 / 12)
    assert nf.sigma_rpm == pytest.approx(expected, rel=0.1)
    assert nf.quant_step_rpm == pytest.approx(q)
    assert nf.period_s == pytest.approx(0.01, rel=1e-3)
    assert nf.jitter_s == pytest.approx(jitter, abs=5e-5 + 0.15 * jitter)
    # a 1000 rpm/s slope turns jitter into speed error
    assert nf.variance(np.array([0.0, 1000.0]))[1] == pytest.approx(nf.sigma_rpm**2 + (1000 * nf.jitter_s) ** 2)


def test_quantisation_step_ignores_unquantised_data() -> None:
    rng = np.random.default_rng(1)
    assert quantisation_step(rng.normal(0, 1, 500)) == 0.0
    assert quantisation_step(np.round(rng.normal(0, 10, 500)) * 0.5) == pytest.approx(0.5)


def _event(tq_t: np.ndarray, tq_v: np.ndarray) -> DiagEvent:
    speed_t = np.arange(0.0, 1.3, 0.01) + 0.004
    return DiagEvent(0, "tip_in", 0.3, 0.0, 1.29, 2000.0, 150.0, tq_t, tq_v, speed_t, np.zeros(speed_t.size),
                     np.ones(speed_t.size), speed_t < 0.22)


def test_torque_quantisation_variance_matches_a_monte_carlo_of_held_torques() -> None:
    """Hold, ramp through zero, hold: the rounding error of each hold acts for the whole hold, the
    inertia integrates it, the pre-event anchor removes its mean. Compare with simulated rounding."""
    rng = np.random.default_rng(5)
    q, inertia = 0.5, 1.5
    tq_t = np.arange(-0.1, 1.4, 0.01)
    errors = []
    shape = np.interp(tq_t, [0.25, 0.35], [-60.0, 120.0])
    for _ in range(400):
        true = shape + np.where(tq_t < 0.3, rng.uniform(-5, 5), rng.uniform(-5, 5))
        true[(tq_t > 0.25) & (tq_t < 0.35)] += rng.uniform(0, q)  # ramp samples: independent errors
        quant = np.round(true / q) * q
        ev = _event(tq_t, quant)
        edges = np.concatenate([[tq_t[0] - 0.005], 0.5 * (tq_t[1:] + tq_t[:-1]), [tq_t[-1] + 0.005]])
        lo = np.maximum(edges[:-1], ev.t_fine[0])
        acted = np.clip(np.minimum(edges[1:][None, :], ev.speed_t[:, None]) - lo[None, :], 0.0, None)
        e = acted @ (quant - true) / inertia * 30 / np.pi
        errors.append(e - e[ev.pre].mean())
    empirical = np.var(np.array(errors), axis=0)
    ev = _event(tq_t, np.round(shape / q) * q)
    model = torque_quantisation_variance(ev, q, inertia)
    late = ev.speed_t > 0.6
    assert model[late] == pytest.approx(empirical[late], rel=0.25)
    assert model[~late].max() < model[late].min()  # it grows with the time since the anchor
    assert np.all(torque_quantisation_variance(ev, 0.0, inertia) == 0.0)  # unquantised torque: no term


def _matrix_reference(ev: DiagEvent, step_nm: float, inertia: float) -> np.ndarray:
    """The quantisation term by its definition: every run's acting time at every sample, as a matrix."""
    tt, vv = ev.torque_t, ev.torque_nm
    edges = np.concatenate([[tt[0] - 0.5 * (tt[1] - tt[0])], 0.5 * (tt[1:] + tt[:-1]),
                            [tt[-1] + 0.5 * (tt[-1] - tt[-2])]])
    first = np.flatnonzero(np.concatenate([[True], np.diff(vv) != 0]))
    last = np.concatenate([first[1:] - 1, [vv.size - 1]])
    start = np.maximum(edges[first], ev.t_fine[0])
    acted = np.clip(np.minimum(edges[last + 1][None, :], ev.speed_t[:, None]) - start[None, :], 0.0, None)
    if ev.pre.any():
        acted -= acted[ev.pre].mean(axis=0)
    return np.asarray(step_nm**2 / 12.0 * (30.0 / np.pi / inertia) ** 2 * np.sum(acted**2, axis=1))


@pytest.mark.parametrize("seed", range(6))
def test_torque_quantisation_variance_equals_its_definition(seed: int) -> None:
    """The prefix-sum form against the (samples, runs) matrix: held, dithered and ramping torques at 20 Hz to
    1 kHz, runs that start before the simulation, anchors of none to a few samples."""
    rng = np.random.default_rng(seed)
    for _ in range(40):
        rate = float(rng.choice([20, 50, 100, 1000]))
        tq_t = np.sort(rng.uniform(-3, 0) + np.cumsum(rng.uniform(0.5, 1.5, int(rng.integers(5, 900))) / rate))
        q = float(rng.choice([0.1, 0.5, 1.0]))
        tq_v = np.round(rng.normal(0, 3, tq_t.size).cumsum() * float(rng.choice([0.0, 0.05, 1.0])) / q) * q
        speed_t = np.arange(0.0, 1.3, 1.0 / float(rng.choice([20, 100, 1000]))) + rng.uniform(0, 0.01)
        ev = DiagEvent(0, "tip_in", 0.3, 0.0, 1.29, 2000.0, 150.0, tq_t, tq_v, speed_t, np.zeros(speed_t.size),
                       np.ones(speed_t.size), speed_t < float(rng.choice([0.0, 0.1, 0.22])))
        want = _matrix_reference(ev, q, 1.5)
        assert torque_quantisation_variance(ev, q, 1.5) == pytest.approx(want, rel=1e-9, abs=1e-12 * want.max())
