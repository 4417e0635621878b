"""Ripple metrics on synthetic speed traces with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.metrics import MetricParams, _knee_fit, knee_fit_in_full, rigid_trend, ripple_metrics
from app.signals import Signal
from tests.analysis.synthetic import damped_response


def _torque(t: np.ndarray, before: float = -50.0, after: float = 150.0) -> Signal:
    return Signal.from_samples("motor_torque_nm", t, np.where(t < 0, before, after))


@pytest.mark.parametrize(
    ("freq", "zeta", "dt"),
    [(8.0, 0.10, 0.001), (6.0, 0.05, 0.01), (10.0, 0.20, 0.002), (4.0, 0.15, 0.005), (7.1, 0.08, 0.01)],
)
def test_damped_sinusoid_gives_back_its_frequency_and_damping_ratio(freq: float, zeta: float, dt: float) -> None:
    t = np.arange(-0.5, 2.5, dt)
    osc = damped_response(t, freq, zeta, 100.0)
    speed = 1500.0 + 30.0 * t + osc  # a road-load ramp under the ripple
    m = ripple_metrics(t, speed, _torque(t), 0.0, 1.0)
    assert m.shuffle_freq_hz == pytest.approx(freq, rel=0.02)
    assert m.damping_ratio == pytest.approx(zeta, rel=0.10)
    # peak to adjacent valley of the analytic response (sampled finely)
    fine = np.arange(0, 1.0 / freq, 1e-5)
    ref = damped_response(fine, freq, zeta, 100.0)
    assert m.fluctuation_rpm == pytest.approx(ref.max() - ref.min(), rel=0.03)
    # settling: the envelope reaches 5 % of the fluctuation, within one period
    sigma = zeta * 2 * np.pi * freq / np.sqrt(1 - zeta**2)
    t_env = np.log(100.0 / (0.05 * m.fluctuation_rpm)) / sigma
    assert m.settling_time_s == pytest.approx(t_env, abs=1.0 / freq)


def _tip(t: np.ndarray, direction: float, rise: float, t_open: float, t_close: float) -> np.ndarray:
    """Quadratic rise of `rise` rpm over the gap, then a damped 7 Hz oscillation from the impact peak."""
    tau = np.clip((t - t_open) / (t_close - t_open), 0.0, 1.0)
    y = np.where(t < t_close, rise * tau**2, 0.0)
    wd, sigma = 2 * np.pi * 7.0, 4.0
    after = rise * np.exp(-sigma * (t - t_close)) * np.cos(wd * (t - t_close))
    return direction * np.where(t >= t_close, after, y)


@pytest.mark.parametrize("direction", [1.0, -1.0])
def test_rise_height_and_rising_edge_time_of_a_tip(direction: float) -> None:
    t = np.arange(-0.5, 2.0, 0.001)
    speed = 3000.0 + _tip(t, direction, 180.0, 0.004, 0.024)
    m = ripple_metrics(t, speed, _torque(t, -50 * direction, 150 * direction), 0.0, direction)
    assert m.rising_edge_time_s == pytest.approx(0.020, abs=0.002)
    assert m.t_rise_start_s == pytest.approx(0.004, abs=0.002)
    assert np.isnan(m.gap_open_time_s)  # the free-rotor estimate needs the rotor-side inertia
    assert m.t_impact_s == pytest.approx(0.024, abs=0.001)
    assert m.rise_height_rpm == pytest.approx(180.0, rel=0.05)
    valley = 180.0 * np.exp(-4.0 * 0.5 / 7.0)
    assert m.fluctuation_rpm == pytest.approx(180.0 + valley, rel=0.03)
    assert m.first_overshoot_rpm == pytest.approx(180.0, rel=0.05)
    assert m.shuffle_freq_hz == pytest.approx(7.0, rel=0.03)


def test_noisy_can_rate_trace_still_gives_frequency() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(-0.5, 2.0, 0.01)
    speed = 2000.0 + damped_response(t, 7.0, 0.1, 80.0) + rng.normal(0, 1.0, t.size)
    m = ripple_metrics(t, speed, _torque(t), 0.0, 1.0)
    assert m.noise_rpm == pytest.approx(1.0, rel=0.5)
    assert m.shuffle_freq_hz == pytest.approx(7.0, rel=0.05)
    assert m.damping_ratio == pytest.approx(0.1, rel=0.3)
    assert m.sample_period_s == pytest.approx(0.01)


def test_rigid_trend_with_known_inertia_removes_the_torque_driven_acceleration() -> None:
    t = np.arange(-0.5, 2.0, 0.002)
    torque = _torque(t)
    gain = 60.0 / (2 * np.pi * 2.0)  # J_eq = 2 kg m^2 at the motor
    integral = np.cumsum(np.r_[0.0, 0.5 * np.diff(t) * (torque.values[1:] + torque.values[:-1])])
    speed = 1000.0 - 5.0 * t + gain * integral
    for g in (gain, None):
        np.testing.assert_allclose(rigid_trend(t, speed, torque, 0.0, g), speed, atol=1e-6)
    osc = damped_response(t, 8.0, 0.1, 50.0)
    m_fixed = ripple_metrics(t, speed + osc, torque, 0.0, 1.0, MetricParams(rigid_gain_rpm_per_nms=gain))
    m_free = ripple_metrics(t, speed + osc, torque, 0.0, 1.0)
    assert m_fixed.fluctuation_rpm == pytest.approx(m_free.fluctuation_rpm, rel=0.02)


def test_a_trace_without_ripple_has_no_metrics() -> None:
    t = np.arange(-0.5, 2.0, 0.01)
    m = ripple_metrics(t, 1000.0 + 10.0 * t, _torque(t), 0.0, 1.0)
    assert np.isnan(m.fluctuation_rpm) and np.isnan(m.shuffle_freq_hz)


@pytest.mark.parametrize("kind", ["rise", "quantised rise", "noise", "fall", "one late sample"])
def test_the_screened_knee_fit_is_the_full_evaluations_to_the_last_bit(kind: str) -> None:
    """Running sums screen the grid, and only points near the screened minimum are evaluated in full: the result
    must be the one every point evaluated in full gives, on long windows far from t = 0 as on short ones."""
    rng = np.random.default_rng(len(kind))
    for _ in range(40):
        n = int(rng.integers(4, 600))
        t = np.asarray(2000.0 * rng.random() + np.arange(n) * float(rng.choice([0.001, 0.005, 0.01, 0.02])),
                       dtype=np.float64)
        x0 = t[0] + rng.random() * (t[-1] - t[0])
        if kind == "rise":
            y = np.maximum(0.0, t - x0) ** rng.uniform(0.5, 3.0) * rng.uniform(1.0, 1e3) + rng.normal(0, 0.5, n)
        elif kind == "quantised rise":
            y = np.round(np.maximum(0.0, t - x0) * 300.0 + rng.normal(0, 0.5, n))
        elif kind == "noise":
            y = rng.normal(0.0, 1.0, n)
        elif kind == "fall":
            y = -100.0 * np.maximum(0.0, t - x0) + rng.normal(0, 0.1, n)
        else:
            y = np.zeros(n)
            y[-1] = 5.0
        assert _knee_fit(t, y) == knee_fit_in_full(t, y)


def test_the_knee_fit_finds_the_knee_of_a_clean_rise() -> None:
    t = np.asarray(10.0 + np.arange(300) * 0.001, dtype=np.float64)
    y = 3.0 + 50.0 * np.maximum(0.0, t - 10.123) ** 2
    t0, base = _knee_fit(t, y)
    assert t0 == pytest.approx(10.123, abs=0.001 / 8)
    assert base == pytest.approx(3.0, abs=1e-6)
