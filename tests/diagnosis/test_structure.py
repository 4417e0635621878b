"""Remainder statistics: noise passes, structure shared by events or concentrated at the impact does not."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.decide import DecisionRules, bootstrap_draws
from app.analysis.diagnosis.structure import Remainder, _locked, _locked_flips, remainder_test

RULES = DecisionRules(n_boot=500)
H, K = 8, 130  # held-out events, locked bins (one sample per bin)
IMPACT = slice(30, 37)  # the bins of the lash traverse and impact


def make(rng: np.random.Generator, shared: float = 0.0, impact: float = 0.0, scale: float = 1.0) -> Remainder:
    """Residuals in noise units: white noise x ``scale`` plus a response shared by all events of a kind
    (``shared`` sigmas, a damped oscillation) and a spike of ``impact`` sigmas in the impact bins."""
    t = np.arange(K) * 0.01
    response = shared * np.exp(-t) * np.sin(2 * np.pi * 6 * t)
    kinds = np.array([0, 1] * (H // 2))
    r = scale * rng.normal(size=(H, K)) + response * np.where(kinds == 0, 1.0, -1.0)[:, None]
    r[:, IMPACT] += impact * rng.choice([-1.0, 1.0], size=(H, 1))
    chi2 = (r**2).sum(axis=1)
    imp = (r[:, IMPACT] ** 2).sum(axis=1)
    return Remainder(chi2, np.full(H, float(K)), imp, np.full(H, float(IMPACT.stop - IMPACT.start)), r,
                     np.ones((H, K)), kinds)


def above(rem: Remainder) -> list[str]:
    t = remainder_test(rem, bootstrap_draws(H, RULES, 1), RULES.level)
    return t.above_noise(RULES.min_gap_ratio, RULES.min_gap_ratio_lo)


@pytest.mark.parametrize("seed", range(6))
def test_white_noise_is_noise_like(seed: int) -> None:
    rem = make(np.random.default_rng(seed))
    t = remainder_test(rem, bootstrap_draws(H, RULES, 1))
    assert t.overall.value == pytest.approx(1.0, abs=0.15)
    assert t.locked == pytest.approx(1.0, abs=0.3)
    assert above(rem) == []


def test_a_small_response_shared_by_every_event_is_structure() -> None:
    """A common response of about half a sigma RMS barely moves the overall ratio but adds up across events."""
    rem = make(np.random.default_rng(1), shared=1.3)
    t = remainder_test(rem, bootstrap_draws(H, RULES, 1))
    assert t.overall.value < RULES.min_gap_ratio  # the total alone would call it noise
    assert t.locked > 2.0 and t.locked_p < 0.05  # 4 events per kind: the smallest p is 1/64
    assert above(rem) == ["locked"]


def test_a_remainder_at_the_impact_is_structure() -> None:
    rem = make(np.random.default_rng(2), impact=3.0)
    assert "impact" in above(rem)


def test_noise_larger_than_the_floor_says_so_overall_but_not_locked() -> None:
    """Scaled noise is a wrong noise floor, not structure: the sign-flip null scales with it."""
    rem = make(np.random.default_rng(3), scale=1.6)
    t = remainder_test(rem, bootstrap_draws(H, RULES, 1))
    assert "overall" in above(rem) and "locked" not in above(rem)
    assert t.locked_p > 0.05


def test_report_form_is_json_ready() -> None:
    t = remainder_test(make(np.random.default_rng(4)), bootstrap_draws(H, RULES, 1))
    d = t.to_dict()
    assert set(d) == {"overall", "impact", "locked", "phases"} and d["phases"] == {}
    assert set(d["locked"]) == {"value", "p_value", "null_95"}  # type: ignore[arg-type]


def test_a_remainder_confined_to_one_phase_is_structure() -> None:
    """Noise everywhere, but 2.5x the noise energy in the oscillation phase: diluted overall, named by phase."""
    from dataclasses import replace

    rng = np.random.default_rng(5)
    rem = make(rng)
    n_ph = np.tile([20.0, 60.0], (H, 1))  # pre-event and oscillation samples per event
    chi_ph = n_ph * np.array([1.0, 2.5]) * rng.uniform(0.9, 1.1, size=(H, 2))
    t = remainder_test(replace(rem, phase_chi2=chi_ph, phase_n=n_ph), bootstrap_draws(H, RULES, 1))
    ratios = dict(t.phases)
    assert ratios["oscillation"].value == pytest.approx(float(chi_ph[:, 1].sum() / n_ph[:, 1].sum()), rel=1e-12)
    assert ratios["oscillation"].lo > 2.0 and ratios["pre_event"].value < 1.2
    assert t.above_noise(RULES.min_gap_ratio, RULES.min_gap_ratio_lo) == ["phase:oscillation"]
    assert set(t.to_dict()["phases"]) == {"pre_event", "oscillation"}  # type: ignore[arg-type]


@pytest.mark.parametrize("seed", range(4))
def test_the_sign_flip_null_is_the_chunked_one_bit_for_bit(seed: int) -> None:
    """The event-locked null accumulated event by event (without the (flips, events, bins) arrays) gives the numbers
    of the statistic evaluated on every sign-flipped copy, so the p-value and the 95th percentile are unchanged."""
    rng = np.random.default_rng(seed)
    h, k = int(rng.integers(3, 30)), int(rng.integers(2, 200))
    lsum = rng.normal(size=(h, k)) * rng.exponential(10.0, size=(h, 1))
    lcnt = rng.integers(0, 4, size=(h, k)).astype(np.float64)
    lsum[lcnt == 0] = 0.0
    kinds = rng.integers(0, 2, size=h)
    signs = rng.choice(np.array([-1.0, 1.0]), size=(1000, h))
    chunked = np.concatenate([_locked(lsum[None] * sg[:, :, None], lcnt[None], kinds[None])
                              for sg in (signs[i:i + 200] for i in range(0, 1000, 200))])
    assert np.array_equal(_locked_flips(lsum, lcnt, kinds, signs), chunked, equal_nan=True)
