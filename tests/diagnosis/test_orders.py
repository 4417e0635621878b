"""Motor-order tones: found by order tracking, kept out of the noise floor, reported as structured remainder.

A tone locked to the rotor angle (torque ripple, a resolver error) sampled at 100 Hz looks like
white noise to a second-difference estimator; counted as noise it raised the floor of an
independent-generator drive from 0.6 to 7.3 rpm and hid the ripple as ``no_significant_gap``.
"""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals, report_dict
from app.analysis.diagnosis.decide import Decision, remainder_field, with_tones
from app.analysis.diagnosis.noise import estimate_noise_floor
from app.analysis.diagnosis.orders import OrderTone, find_order_tones
from tests.diagnosis.conftest import paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals


def _channel(seed: int, amp: float, order: int, sigma: float = 0.6) -> tuple[np.ndarray, np.ndarray]:
    """60 s of a 100 Hz speed channel (jittered stamps, 0.5 rpm steps) sweeping 1 700-3 300 rpm."""
    rng = np.random.default_rng(seed)
    t = 0.01 * np.arange(6000) + rng.normal(0.0, 0.00015, 6000)
    rpm = 2500.0 + 800.0 * np.sin(2 * np.pi * t / 25.0)
    theta = np.cumsum(rpm) * 0.01 * 2 * np.pi / 60.0
    meas = rpm + amp * np.cos(order * theta + 0.7) + rng.normal(0.0, sigma, t.size)
    return t, np.round(meas / 0.5) * 0.5


@pytest.mark.parametrize(("order", "amp"), [(1, 1.0), (3, 2.5), (12, 0.8)])
def test_a_tone_is_found_at_its_order_with_its_amplitude(order: int, amp: float) -> None:
    t, v = _channel(5, amp, order)
    tones, clean, tested = find_order_tones(t, v, np.ones(t.size, bool), 0.01)
    assert [x.order for x in tones] == [order]
    assert tones[0].amplitude_rpm == pytest.approx(amp, rel=0.1)
    assert tones[0].p_value < 1e-6
    # what is left on the tested samples is the white noise (0.6 rpm plus the 0.5 rpm rounding)
    d2 = (clean[2:] - 2 * clean[1:-1] + clean[:-2])[tested[2:] & tested[1:-1] & tested[:-2]]
    assert d2.size > 1000
    assert float(np.std(d2) / np.sqrt(6)) < 0.8


@pytest.mark.parametrize("seed", range(6))
def test_no_tone_on_a_clean_channel(seed: int) -> None:
    t, v = _channel(seed, 0.0, 1)
    tones, clean, _ = find_order_tones(t, v, np.ones(t.size, bool), 0.01)
    assert tones == []
    assert np.array_equal(clean, v)


def test_the_noise_floor_leaves_the_tone_out() -> None:
    t, v = _channel(2, 3.0, 1)
    _, clean_v = _channel(2, 0.0, 1)
    floor = estimate_noise_floor(t, v)
    truth = estimate_noise_floor(t, clean_v)
    assert [x.order for x in floor.tones] == [1]
    assert floor.sigma_rpm == pytest.approx(truth.sigma_rpm, rel=0.15)
    assert floor.to_dict()["tones"][0]["order"] == 1


def test_a_transient_block_does_not_hide_the_tone() -> None:
    t, v = _channel(3, 1.5, 2)
    v = v.copy()
    v[3000:3030] += np.linspace(0.0, 400.0, 30) ** 1.5 / 20.0  # a shuffle burst inside the quiet samples
    tones, _, _ = find_order_tones(t, v, np.ones(t.size, bool), 0.01)
    assert [x.order for x in tones] == [2]


def test_with_tones_never_leaves_explained_and_names_the_order() -> None:
    d = Decision("explained", top=("backlash",), reason="backlash: explained",
                 details={"remainder": remainder_field([], 1.1, explained=True)})
    tone = OrderTone(order=6, amplitude_rpm=1.4, f_stat=40.0, p_value=1e-20, blocks=12)
    out = with_tones(d, [tone])
    assert out.status == "partial"
    assert out.details["remainder"]["status"] == "structured"
    assert out.details["remainder"]["where"] == ["motor order 6 (1.40 rpm)"]
    assert out.details["tones"][0]["order"] == 6
    assert "motor order 6" in out.reason
    assert with_tones(d, []) is d


def test_a_speed_ripple_on_a_drive_is_reported_as_structured_remainder() -> None:
    """A 2nd-order tone on a sim-made drive with no effect: named as structure, never explained."""
    v = paper()
    rng = np.random.default_rng(21)
    drive = make_drive(v, rng, DriveSpec(duration_s=30.0))
    truth = run_truth(v, drive)
    samples = measure(drive, truth, CanSampling(offset_s=0.006), rng)
    t, rpm = samples["motor_speed_rpm"]
    fine_t = np.asarray(truth.t)
    theta = np.interp(t, fine_t, np.cumsum(np.asarray(truth.motor_speed_rpm)) * float(fine_t[1] - fine_t[0])
                      * 2 * np.pi / 60.0)
    samples["motor_speed_rpm"] = (t, rpm + 3.0 * np.cos(2.0 * theta))
    res = diagnose_signals(to_signals(samples), v, DiagnosisOptions(seed=2))
    doc = report_dict(res)
    assert [x["order"] for x in doc["noise_floor"]["tones"]] == [2]
    assert res.decision.status != "explained"
    assert doc["decision"]["remainder"]["status"] == "structured"
    assert any("motor order 2" in w for w in doc["decision"]["remainder"]["where"])
