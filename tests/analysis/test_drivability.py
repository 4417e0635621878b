"""Drivability criteria against analytic accelerations: a second-order step response (the shuffle),
a clunk burst at a known time, a pedal step at a known time, and the ISO 2631-1 W_d table."""

from __future__ import annotations

import math

import numpy as np
import pytest

from app.analysis.drivability import DrivabilityParams, drivability_criteria
from app.analysis.iso2631 import vdv, wd_gain
from app.signals import Signal

PRE, SET = -0.3, 1.5  # m/s^2 before and long after the tip-in


def step_response(t: np.ndarray, f_hz: float, zeta: float, t0: float = 0.0, pre: float = PRE,
                  settled: float = SET) -> np.ndarray:
    """Acceleration of an underdamped second-order system stepping from ``pre`` to ``settled`` at ``t0``;
    ``f_hz`` is the damped frequency. Its extrema sit at ``t0 + k / (2 f)``."""
    wd = 2 * math.pi * f_hz
    sig = zeta * wd / math.sqrt(1 - zeta**2)
    tau = np.maximum(t - t0, 0.0)
    resp = 1 - np.exp(-sig * tau) * (np.cos(wd * tau) + sig / wd * np.sin(wd * tau))
    return np.where(t > t0, pre + (settled - pre) * resp, pre)


def truth(f_hz: float, zeta: float) -> dict[str, float]:
    wd = 2 * math.pi * f_hz
    sig = zeta * wd / math.sqrt(1 - zeta**2)
    over = math.exp(-sig * math.pi / wd)  # first overshoot as a fraction of the step
    step = SET - PRE
    return {"kick": step * over, "pp": step * (over + over**2), "freq": f_hz, "zeta": zeta}


@pytest.mark.parametrize(("f_hz", "zeta"), [(3.0, 0.1), (4.5, 0.15), (6.0, 0.2), (8.0, 0.25)])
def test_shuffle_criteria_of_a_step_response_at_100_hz(f_hz: float, zeta: float) -> None:
    rng = np.random.default_rng(3)
    t = np.arange(-0.5, 1.5, 0.01) + 0.0037
    a = step_response(t, f_hz, zeta) + rng.normal(0.0, 0.03, t.size)
    d = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0)
    ref = truth(f_hz, zeta)
    assert d.kick_ms2 == pytest.approx(ref["kick"], rel=0.05)
    assert d.shuffle_pp_ms2 == pytest.approx(ref["pp"], rel=0.05)
    assert d.shuffle_freq_hz == pytest.approx(f_hz, rel=0.03)
    assert d.shuffle_damping_ratio == pytest.approx(zeta, rel=0.15)
    assert d.settled_accel_ms2 == pytest.approx(SET, abs=0.05)
    assert d.pre_accel_ms2 == pytest.approx(PRE, abs=0.03)
    fine = np.arange(-0.5, 1.5, 1e-4)
    assert d.vdv_ms175 == pytest.approx(vdv(step_response(fine, f_hz, zeta), 1e4), rel=0.05)
    assert d.response_delay_s != d.response_delay_s and d.resolution["response_delay_s"] == "no pedal channel"


def test_tip_out_is_the_mirror_of_a_tip_in() -> None:
    t = np.arange(-0.5, 1.5, 0.01)
    up = drivability_criteria(t, step_response(t, 5.0, 0.12), -0.5, 1.5, 0.0, 1.0)
    down = drivability_criteria(t, step_response(t, 5.0, 0.12, pre=-PRE, settled=-SET), -0.5, 1.5, 0.0, -1.0)
    assert down.kick_ms2 == pytest.approx(up.kick_ms2, rel=1e-6)
    assert down.shuffle_pp_ms2 == pytest.approx(up.shuffle_pp_ms2, rel=1e-6)
    assert down.settled_accel_ms2 == pytest.approx(-up.settled_accel_ms2, rel=1e-6)


def test_response_delay_from_the_pedal_step_to_the_first_rise() -> None:
    t = np.arange(-0.5, 1.5, 0.01)
    t0 = 0.12  # the acceleration starts rising 120 ms after the torque crossing reference
    a = step_response(t, 4.0, 0.15, t0=t0)
    pedal_t = np.arange(-0.5, 1.5, 0.01)
    pedal = Signal("pedal_pct", pedal_t, np.where(pedal_t >= -0.05, 40.0, 0.0), "%")
    d = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0, pedal=pedal)
    # the step response passes 10 % of its first peak height a few ms after t0
    fine = np.arange(t0, t0 + 0.2, 1e-5)
    resp = step_response(fine, 4.0, 0.15, t0=t0)
    t_rise = fine[np.argmax(resp - PRE >= 0.1 * (resp.max() - PRE))]
    t_pedal = -0.06 + 0.01 * (4.0 / 40.0)  # 10 % of the step (4 %) reached between the samples at -0.06 and -0.05
    assert d.response_delay_s == pytest.approx(t_rise - t_pedal, abs=0.004)


def test_clunk_is_the_high_frequency_peak_at_lash_closure() -> None:
    t = np.arange(-0.5, 1.5, 0.001)
    base = step_response(t, 4.0, 0.15)
    burst = 0.8 * np.exp(-np.maximum(t - 0.05, 0) / 0.01) * np.sin(2 * np.pi * 90 * (t - 0.05)) * (t >= 0.05)
    quiet = drivability_criteria(t, base, -0.5, 1.5, 0.0, 1.0, t_close=0.05)
    loud = drivability_criteria(t, base + burst, -0.5, 1.5, 0.0, 1.0, t_close=0.05)
    assert loud.clunk_ms2 == pytest.approx(0.8 * 0.84, rel=0.2)  # a 20-200 Hz band keeps most of a 90 Hz burst
    assert quiet.clunk_ms2 < 0.1 * loud.clunk_ms2
    assert loud.shuffle_pp_ms2 == pytest.approx(quiet.shuffle_pp_ms2, rel=0.03)  # the clunk is not the shuffle
    coarse = drivability_criteria(t[::25], (base + burst)[::25], -0.5, 1.5, 0.0, 1.0, t_close=0.05)  # 40 Hz
    assert math.isnan(coarse.clunk_ms2) and "cannot carry the clunk band" in coarse.resolution["clunk_ms2"]


def test_max_jerk_of_a_smooth_rise() -> None:
    t = np.arange(-0.5, 1.5, 0.002)
    rise = 0.2  # s; a = 1 - cos rise from 0 to 2 m/s^2: largest jerk 2 pi / (2 rise) = 15.7 m/s^3 half-way
    a = np.where(t <= 0, 0.0, np.where(t >= rise, 2.0, 1.0 - np.cos(np.pi * np.clip(t, 0, rise) / rise)))
    d = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0)
    assert d.max_jerk_ms3 == pytest.approx(2.0 * np.pi / (2 * rise), rel=0.03)
    assert d.settled_accel_ms2 == pytest.approx(2.0, abs=1e-3)


@pytest.mark.parametrize(("f_hz", "iso"), [(1.0, 1.011), (2.0, 0.890), (4.0, 0.512), (8.0, 0.253), (16.0, 0.125)])
def test_wd_weighting_follows_the_iso_2631_table(f_hz: float, iso: float) -> None:
    assert float(wd_gain(f_hz)) == pytest.approx(iso, rel=0.01)


@pytest.mark.parametrize("fs", [100.0, 1000.0])
def test_vdv_of_a_sine_is_its_weighted_amplitude_times_the_fourth_root_of_3T_over_8(fs: float) -> None:
    f, amp, dur = 4.0, 1.2, 20.0
    t = np.arange(0.0, dur, 1.0 / fs)
    v = vdv(amp * np.sin(2 * np.pi * f * t), fs)
    expected = amp * float(wd_gain(f)) * (3 * dur / 8) ** 0.25
    assert v == pytest.approx(expected, rel=0.03)


def test_a_constant_acceleration_has_no_dose() -> None:
    assert vdv(np.full(500, 2.0), 100.0) == pytest.approx(0.0, abs=1e-9)


def test_saturated_and_unresolved_criteria_are_null_with_a_reason() -> None:
    t = np.arange(-0.5, 1.5, 0.01)
    a = step_response(t, 6.0, 0.1)
    sat = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0, saturated=True)
    assert math.isnan(sat.kick_ms2) and "saturated" in sat.resolution["kick_ms2"]
    assert math.isfinite(sat.settled_accel_ms2)
    slow = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0, bandwidth_hz=8.0, shuffle_hint_hz=6.0)
    assert math.isnan(slow.shuffle_pp_ms2) and slow.resolution["shuffle_pp_ms2"].startswith("unresolved")
    ok = drivability_criteria(t, a, -0.5, 1.5, 0.0, 1.0, bandwidth_hz=14.0, shuffle_hint_hz=6.0)
    assert math.isfinite(ok.shuffle_pp_ms2) and ok.resolution["clunk_ms2"].startswith("unresolved")


def test_too_short_or_empty_traces_give_nan_not_an_exception() -> None:
    t = np.arange(0.0, 0.05, 0.01)
    d = drivability_criteria(t, np.zeros(t.size), 0.0, 0.05, 0.02, 1.0)
    assert all(math.isnan(v) for v in d.values().values())
    flat = np.arange(-0.5, 1.5, 0.01)
    d = drivability_criteria(flat, np.zeros(flat.size), -0.5, 1.5, 0.0, 1.0)
    assert math.isnan(d.kick_ms2) and "no acceleration peak" in d.resolution["kick_ms2"]


def test_parameters_are_checked() -> None:
    with pytest.raises(ValueError, match="cut-offs"):
        DrivabilityParams(clunk_band_hz=(50.0, 20.0))


def test_damped_sine_fallback_is_quiet_when_a_trial_step_overflows() -> None:
    """A growing, noisy window sends MINPACK's trial steps to a negative decay whose exp overflows; the step is
    rejected, and the fallback fit says nothing on stderr (it did: 'overflow encountered in exp' in a benchmark)."""
    import warnings

    from app.analysis.drivability import _minpack_fit

    rng = np.random.default_rng(1)
    for _ in range(18):  # the 18th draw of this generator overflows
        n = int(rng.integers(20, 800))
        dt = float(rng.choice([0.001, 0.01]))
        tau = np.arange(n) * dt
        g, f = rng.uniform(-50, 50), rng.uniform(2, 15)
        ym = (rng.normal(size=n) * rng.uniform(0.001, 1)
              + np.exp(np.clip(g * tau, -50, 50)) * np.cos(2 * math.pi * f * tau) * rng.uniform(0.01, 5))
        x0 = np.array([0.0, rng.normal(), rng.uniform(0, 20), 2 * math.pi * f * rng.uniform(0.7, 1.3),
                       rng.uniform(-3, 3)])
    assert g > 30 and n > 300  # the overflowing draw: a fast-growing oscillation
    with np.errstate(over="raise"), pytest.raises(FloatingPointError):  # the model's exp overflows on it ...
        for sig in np.linspace(0.0, -3000.0, 7):
            np.exp(-sig * tau)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # ... and the fit stays quiet
        fit = _minpack_fit(tau, ym, x0, 2 * math.pi * f)
    assert fit is None or (math.isfinite(fit.sig) and fit.sig >= 0.0)
