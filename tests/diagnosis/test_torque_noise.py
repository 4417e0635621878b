"""White noise on the logged torque: estimated from the log, propagated through the model, not a gap.

An inverter's torque estimate carries noise the air-gap torque does not have. Driven by the noisy
samples, the simulated driveline rings where the real one does not; unaccounted, that alone put a
no-effect drive at several times the noise floor.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals, report_dict
from app.analysis.diagnosis.forward import DiagEvent, Nuisance, simulate_events
from app.analysis.diagnosis.noise import white_noise_sigma
from app.analysis.diagnosis.uncertainty import torque_noise_variance
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals


def _torque(t: np.ndarray) -> np.ndarray:
    """Hold, ramp through zero at 0.3 s (600 N m/s), hold."""
    return np.interp(t, [0.2, 0.45], [-50.0, 100.0])


@pytest.mark.parametrize("sigma", [0.0, 0.3, 1.2])
def test_white_noise_sigma_of_a_ramping_held_torque(sigma: float) -> None:
    rng = np.random.default_rng(3)
    t = 0.01 * np.arange(4000) + 0.002
    levels = np.repeat(rng.uniform(-60, 120, 40), 100)  # 1 s holds joined by 10 ms steps
    v = np.round((levels + rng.normal(0.0, sigma, t.size)) / 0.1) * 0.1 if sigma else levels
    got = white_noise_sigma(t, v)
    if sigma == 0.0:
        assert got == 0.0  # held values: no white noise (their rounding is the quantisation term's)
    else:
        assert got == pytest.approx(np.hypot(sigma, 0.1 / np.sqrt(12)), rel=0.1)


def _event() -> DiagEvent:
    tq_t = np.arange(-4.0, 1.4, 0.01) + 0.003
    speed_t = np.arange(0.0, 1.3, 0.01) + 0.007
    return DiagEvent(0, "tip_in", 0.3, 0.0, 1.3, 2000.0, 150.0, tq_t, _torque(tq_t), speed_t, np.zeros(speed_t.size),
                     np.ones(speed_t.size), speed_t < 0.22, sim_t0=-3.9, speed_init_rpm=2000.0)


def test_torque_noise_variance_matches_an_independent_monte_carlo() -> None:
    """The function's few draws, smoothed over 50 ms, agree with 60 other draws of the same noise."""
    ev, veh, nui, sigma = _event(), paper(), Nuisance(), 0.5
    var = torque_noise_variance([ev], veh, nui, sigma, seed=11)[0]
    ref = simulate_events([ev], veh, 1.0, ())[0].at(ev.speed_t, 0.0)
    rng = np.random.default_rng(99)
    diffs = []
    for _ in range(60):
        noisy = replace(ev, torque_nm=ev.torque_nm + rng.normal(0.0, sigma, ev.torque_nm.size))
        d = simulate_events([noisy], veh, 1.0, ())[0].at(ev.speed_t, 0.0) - ref
        diffs.append(d - d[ev.pre].mean())
    empirical = np.mean(np.array(diffs) ** 2, axis=0)
    assert float(np.sqrt(empirical.mean())) > 0.3  # rpm: half a N m of noise makes the paper vehicle ring
    assert float(var.mean()) == pytest.approx(float(empirical.mean()), rel=0.35)
    assert np.all(torque_noise_variance([ev], veh, nui, 0.0)[0] == 0.0)


def test_no_effect_drive_with_a_noisy_torque_channel_has_no_significant_gap() -> None:
    v = paper()
    rng = np.random.default_rng(21)
    drive = make_drive(v, rng, DriveSpec(duration_s=30.0))
    signals = to_signals(measure(drive, run_truth(v, drive), CanSampling(offset_s=0.006, torque_noise_nm=0.6), rng))
    res = diagnose_signals(signals, v, DiagnosisOptions(seed=2))
    doc = report_dict(res)
    assert res.noise.torque_sigma_nm == pytest.approx(np.hypot(0.6, 0.5 / np.sqrt(12)), rel=0.2)
    assert doc["noise_floor"]["torque_sigma_nm"] == pytest.approx(res.noise.torque_sigma_nm, rel=1e-3)
    assert res.decision.status == "no_significant_gap", res.decision.reason


def test_white_noise_sigma_has_no_quantisation_steps() -> None:
    """0.3 N m of noise on a 0.1 N m DBC step: the MAD of the second differences moves in whole steps (it
    read 0.24 and 0.30 N m on two drives with the same noise); the trimmed RMS does not."""
    got = []
    for seed in range(6):
        rng = np.random.default_rng(100 + seed)
        t = 0.01 * np.arange(1500) + 0.004
        levels = np.repeat(rng.uniform(-60, 120, 15), 100)
        got.append(white_noise_sigma(t, np.round((levels + rng.normal(0.0, 0.3, t.size)) / 0.1) * 0.1))
    truth = np.hypot(0.3, 0.1 / np.sqrt(12))
    assert np.all(np.abs(np.array(got) / truth - 1.0) < 0.1), got
