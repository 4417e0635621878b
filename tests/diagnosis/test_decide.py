"""The decision rules on held-out scores with known structure (no simulator involved)."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.decide import CandidateScore, DecisionRules, bootstrap_draws, decide, score_candidate

RULES = DecisionRules(n_boot=500)
N = np.full(8, 100.0)  # 8 held-out events, 100 samples each: pure noise gives chi2 ~ 100 per event


def cand(cid: str, base: np.ndarray, left: float, spread: float = 0.02, seed: int = 0) -> CandidateScore:
    """A candidate leaving ``left`` of the excess over noise on every event (with a little scatter)."""
    rng = np.random.default_rng(seed)
    chi2 = N + (base - N) * np.clip(left + rng.normal(0, spread, base.size), 0, None)
    return score_candidate(cid, tuple(cid.split("+")), base, chi2, N, bootstrap_draws(8, RULES, 1), RULES)


BASE = N * np.array([8.0, 12.0, 9.0, 15.0, 10.0, 7.0, 11.0, 13.0])


def run(singles: list[CandidateScore], pairs: list[CandidateScore] | None = None, base: np.ndarray = BASE,
        n_cal: int = 8) -> tuple[str, tuple[str, ...], tuple[str, ...]]:
    d = decide(base, N, singles, pairs or [], bootstrap_draws(8, RULES, 1), RULES, n_cal)
    return d.status, d.top, d.confusable


def test_explained_when_one_candidate_removes_nearly_all_of_the_excess() -> None:
    assert run([cand("torque_lag", BASE, 0.03), cand("speed_sensor", BASE, 0.6, seed=1),
                cand("drag", BASE, 1.0, seed=2)]) == ("explained", ("torque_lag",), ())


def test_partial_when_most_is_left_over() -> None:
    assert run([cand("backlash", BASE, 0.55), cand("drag", BASE, 1.0, seed=2)])[:2] == ("partial", ("backlash",))


def test_ambiguous_names_the_confusable_pair() -> None:
    status, _, pair = run([cand("torque_lag", BASE, 0.05, spread=0.05),
                             cand("speed_sensor", BASE, 0.06, spread=0.05, seed=1)])
    assert status == "ambiguous"
    assert set(pair) == {"torque_lag", "speed_sensor"}


def test_no_significant_gap_when_the_baseline_sits_on_the_noise_floor() -> None:
    base = N * np.array([1.05, 0.95, 1.1, 1.0, 0.9, 1.2, 1.0, 1.02])
    assert run([cand("drag", base, 0.5)], base=base)[0] == "no_significant_gap"


def test_none_of_candidates_when_nothing_removes_a_significant_share() -> None:
    assert run([cand("drag", BASE, 0.95), cand("backlash", BASE, 1.02, seed=3)])[0] == "none_of_candidates"


def test_a_lookalike_that_leaves_half_the_excess_is_never_explained() -> None:
    status, _, _ = run([cand("housing_mount", BASE, 0.45)])
    assert status == "partial"


def test_greedy_pair_accepted_only_when_clearly_better() -> None:
    single = cand("backlash", BASE, 0.5)
    good_pair = cand("backlash+drag", BASE, 0.05, seed=4)
    assert run([single, cand("drag", BASE, 0.7, seed=5)], [good_pair])[:2] == ("explained", ("backlash", "drag"))
    no_better = cand("backlash+drag", BASE, 0.48, seed=4)
    assert run([single, cand("drag", BASE, 0.7, seed=5)], [no_better])[:2] == ("partial", ("backlash",))


@pytest.mark.parametrize(("n_cal", "n_ho"), [(2, 8), (8, 2)])
def test_insufficient_data_with_reason(n_cal: int, n_ho: int) -> None:
    base, n = BASE[:n_ho], N[:n_ho]
    d = decide(base, n, [], [], bootstrap_draws(n_ho, RULES, 1), RULES, n_cal)
    assert d.status == "insufficient_data"
    assert "at least 3" in d.reason


def test_a_close_lookalike_leaving_a_clear_remainder_is_partial() -> None:
    """90 % of a large gap removed but the rest is still 14x the noise: not an explanation."""
    big = N * np.array([120.0, 150.0, 130.0, 160.0, 140.0, 125.0, 135.0, 145.0])
    assert run([cand("speed_sensor", big, 0.09, spread=0.01)], base=big)[:2] == ("partial", ("speed_sensor",))
    # the same share with the remainder near the noise floor is explained
    small = N * np.array([8.0, 12.0, 9.0, 15.0, 10.0, 7.0, 11.0, 13.0])
    assert run([cand("speed_sensor", small, 0.09, spread=0.01)], base=small)[0] == "explained"
