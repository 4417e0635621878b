from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.forward import DiagEvent, torque_input
from app.analysis.diagnosis.localise import band_energy, coherence_by_band, residual_torque_lag
from sim.effects.base import Effect, ParamSpec


def test_band_energy_is_a_parseval_split() -> None:
    rng = np.random.default_rng(0)
    y = rng.normal(0, 1, 130)
    e = band_energy(y, 0.01)
    assert sum(e.values()) == pytest.approx(float(y @ y), rel=1e-9)
    t = 0.01 * np.arange(200)
    shuffle = band_energy(np.sin(2 * np.pi * 7.0 * t), 0.01)
    assert shuffle["2-12Hz"] > 0.95 * sum(shuffle.values())


def test_coherence_is_high_for_a_consistent_linear_response_and_low_for_noise() -> None:
    rng = np.random.default_rng(1)
    torques = [np.cumsum(rng.normal(0, 1, 128)) for _ in range(8)]
    linear = [np.convolve(q, [0.5, 0.3, 0.2], mode="same") for q in torques]
    noise = [rng.normal(0, 1, 128) for _ in range(8)]
    assert coherence_by_band(linear, torques, 0.01)["2-12Hz"] > 0.9
    assert coherence_by_band(noise, torques, 0.01)["2-12Hz"] < 0.4


def test_residual_lag_finds_a_delayed_response() -> None:
    rng = np.random.default_rng(2)
    q = [np.cumsum(rng.normal(0, 1, 200)) for _ in range(4)]
    r = [np.concatenate([np.zeros(3), np.gradient(x)[:-3]]) for x in q]  # the residual follows dT/dt by 30 ms
    lag, peak = residual_torque_lag(r, q, 0.01)
    assert lag == pytest.approx(0.03) and peak > 0.5


def test_input_transform_hook_reaches_the_simulated_torque() -> None:
    half = Effect("half", "halved torque", (ParamSpec("k", "-", 0.0, 1.0, 1.0),),
                  input_transform=lambda t, q, v: q * v["k"])
    t = 0.01 * np.arange(60)
    ev = DiagEvent(0, "tip_in", 0.3, 0.05, 0.5, 2000.0, 100.0, t, np.linspace(-50, 50, 60), t[5:50],
                   np.full(45, 2000.0), np.ones(45), t[5:50] < 0.2)
    base = torque_input(ev, 1.0, ())
    assert np.allclose(torque_input(ev, 1.0, [(half, {"k": 0.5})]), 0.5 * base)
