from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.noise import estimate_noise_floor, quantisation_step


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
