"""Sampling adequacy on a bursty ~48 Hz stream (bursts of 2-3 frames 1-5 ms apart every 40-60 ms)."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.metrics import MetricParams, RippleMetrics, ripple_metrics
from app.analysis.sampling import spacing, uniform_by_timestamps
from app.analysis.series import median_period
from app.signals import Signal
from tests.analysis.synthetic import damped_response


def bursty_times(t0: float, t1: float, seed: int = 11) -> np.ndarray:
    """Frame times of an inverter that sends 2-3 frames 1-5 ms apart, a burst every 40-60 ms."""
    rng = np.random.default_rng(seed)
    out: list[float] = []
    t = t0
    while t < t1:
        k = int(rng.integers(2, 4))
        out.extend(t + np.concatenate(([0.0], np.cumsum(rng.uniform(0.001, 0.005, k - 1)))))
        t += float(rng.uniform(0.040, 0.060))
    return np.array([x for x in out if x < t1])


def test_bursty_stream_period_is_the_mean_spacing_not_the_median() -> None:
    t = bursty_times(0.0, 60.0)
    sp = spacing(t)
    assert sp.bursty
    assert sp.mean_s == pytest.approx(0.020, abs=0.0015)  # 2.5 frames per 50 ms
    assert 1.0 / sp.mean_s == pytest.approx(50.0, rel=0.08)
    assert sp.median_s < 0.006 and median_period(t) == sp.median_s  # what the median would have claimed
    assert 0.055 < sp.max_s <= 0.060
    regular = np.arange(0.0, 10.0, 0.01) + np.random.default_rng(1).normal(0.0, 0.0003, 1000)
    sr = spacing(np.sort(regular))
    assert not sr.bursty and sr.mean_s == pytest.approx(0.01, rel=0.01)


def test_bursty_stream_is_resampled_by_its_time_stamps_at_the_mean_spacing() -> None:
    t = bursty_times(0.0, 5.0)
    y = 100.0 * np.sin(2 * np.pi * 1.5 * t)
    grid, yu, sp = uniform_by_timestamps(t, y)
    assert np.allclose(np.diff(grid), sp.mean_s)
    assert grid[0] == t[0] and grid[-1] <= t[-1]
    assert np.max(np.abs(yu - 100.0 * np.sin(2 * np.pi * 1.5 * grid))) < 6.0  # linear between bursts 60 ms apart
    tr = np.arange(0.0, 1.0, 0.01)
    same_t, _, _ = uniform_by_timestamps(tr, np.sin(tr))
    assert same_t is tr  # a regular stream is left alone


def _metrics(freq: float) -> RippleMetrics:
    t = bursty_times(-0.5, 2.5)
    speed = 1500.0 + 30.0 * t + damped_response(t, freq, 0.08, 100.0) + np.random.default_rng(2).normal(0, 1.5, t.size)
    torque = Signal.from_samples("motor_torque_nm", t, np.where(t < 0, -50.0, 150.0))
    return ripple_metrics(t, speed, torque, 0.0, 1.0, MetricParams(free_rotor_inertia_kgm2=0.044))


def test_slow_shuffle_is_measured_and_the_gap_open_time_is_flagged_not_printed() -> None:
    m = _metrics(3.2)
    assert m.sample_period_s == pytest.approx(0.0196, abs=0.001)
    assert m.shuffle_freq_hz == pytest.approx(3.2, rel=0.03)
    assert m.noise_rpm == pytest.approx(1.5, rel=0.2)  # from the logged samples
    assert np.isnan(m.gap_open_time_s)
    assert m.resolution == {
        "gap_open_time_s": "sampling too coarse for the gap-open time: mean spacing 19.6 ms, max 58.3 ms; "
                           "needs a mean spacing <= 12 ms"}


def test_fast_shuffle_at_48_hz_bursts_is_null_with_the_reason() -> None:
    m = _metrics(12.0)
    assert np.isnan(m.shuffle_freq_hz) and np.isnan(m.damping_ratio)
    why = m.resolution["shuffle_freq_hz"]
    assert why.startswith("sampling too coarse for the shuffle:") and "needs 6 (3 at the longest gap)" in why
    assert m.resolution["damping_ratio"] == why
    assert m.resolution["fluctuation_rpm"].startswith("approximate:")
    assert np.isfinite(m.fluctuation_rpm)  # kept, flagged


def test_regular_1khz_sampling_resolves_everything() -> None:
    t = np.arange(-0.5, 2.5, 0.001)
    speed = 1500.0 + damped_response(t, 12.0, 0.08, 100.0)
    m = ripple_metrics(t, speed, Signal.from_samples("motor_torque_nm", t, np.where(t < 0, -50.0, 150.0)), 0.0, 1.0)
    assert m.resolution == {} and m.shuffle_freq_hz == pytest.approx(12.0, rel=0.02)


def test_analysis_and_diagnosis_take_the_period_by_one_rule() -> None:
    """The bursty stream's period is its mean spacing for the diagnosis' noise floor as for the analysis (the
    median of the spacings said 4 ms where the stream delivers one value every 20 ms); a regular stream with
    drop-outs keeps its nominal period in both."""
    from app.analysis.diagnosis.noise import estimate_noise_floor
    from app.analysis.sampling import sample_period
    from app.pipeline import AnalysisOptions, analyze_signals
    from sim import load_vehicle
    from tests.analysis.synthetic import drive

    t = bursty_times(0.0, 60.0)
    y = 1500.0 + np.random.default_rng(3).normal(0.0, 1.0, t.size)
    assert sample_period(t) == pytest.approx(spacing(t).mean_s, rel=1e-12) and 0.0195 < sample_period(t) < 0.0205
    assert estimate_noise_floor(t, y).period_s == sample_period(t)
    keep = np.random.default_rng(4).random(3000) > 0.05
    regular = np.arange(0.0, 30.0, 0.01)[keep]
    assert spacing(regular).mean_s == pytest.approx(0.0105, abs=0.0003)
    assert sample_period(regular) == pytest.approx(0.01)
    ss = drive(speed_gap=(6.0, 6.02))  # one drop-out
    res = analyze_signals(ss, load_vehicle("paper"), AnalysisOptions())
    assert res.whole is not None
    assert float(res.whole.t[1] - res.whole.t[0]) == pytest.approx(sample_period(ss["motor_speed_rpm"].t)) == 0.01
