"""The rating model: monotone, recovers a known rule, refuses too few events and bad scores, versioned."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.analysis.ratings import FEATURES, MIN_EVENTS, RatingModel, apply_ratings, fit_ratings
from app.errors import InputError, InsufficientDataError


def rule(x: np.ndarray) -> np.ndarray:
    pp, kick, jerk, clunk, delay, _ = x.T
    return np.clip(9.6 - 1.5 * pp - 0.6 * kick - 0.025 * jerk - 4.0 * clunk - 6.0 * np.maximum(0, delay - 0.12), 1, 10)


def draw(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack((rng.uniform(0.1, 2.5, n), rng.uniform(0.05, 1.5, n), rng.uniform(8, 90, n),
                            rng.uniform(0.0, 0.4, n), rng.uniform(0.05, 0.3, n), rng.uniform(0.4, 2.0, n)))


@pytest.fixture(scope="module")
def fitted() -> tuple[RatingModel, np.random.Generator]:
    rng = np.random.default_rng(5)
    x = draw(rng, 60)
    scores = np.clip(np.round((rule(x) + rng.normal(0, 0.3, 60)) * 2) / 2, 1, 10)
    return fit_ratings(x, scores), rng


def test_the_fit_recovers_a_known_rule_from_60_noisy_scores(fitted: tuple[RatingModel, np.random.Generator]) -> None:
    model, rng = fitted
    assert model.events == 60 and model.features == FEATURES
    assert 0.2 < model.cv_rms <= 0.5  # the scores' own noise is 0.3 points
    fresh = draw(rng, 400)
    err = model.predict(fresh) - rule(fresh)
    assert float(np.sqrt(np.mean(err**2))) < 0.35


def test_the_score_never_rises_when_a_criterion_grows(fitted: tuple[RatingModel, np.random.Generator]) -> None:
    model, rng = fitted
    base = draw(rng, 50)
    for j in range(len(FEATURES)):
        worse = base.copy()
        worse[:, j] *= 1.5
        assert np.all(model.predict(worse) <= model.predict(base) + 1e-12)
    assert np.all((model.predict(base * 10) >= 1.0) & (model.predict(base * 0) <= 10.0))


def test_too_few_events_and_bad_scores_are_refused() -> None:
    rng = np.random.default_rng(1)
    x = draw(rng, MIN_EVENTS - 1)
    with pytest.raises(InsufficientDataError, match=f"needs at least {MIN_EVENTS}") as info:
        fit_ratings(x, rule(x))
    assert info.value.code == "ratings_too_few_events"
    x = draw(rng, 30)
    scores = rule(x)
    scores[4] = 11.0
    with pytest.raises(InputError, match="not in 1-10") as bad:
        fit_ratings(x, scores)
    assert bad.value.code == "ratings_score"
    with pytest.raises(InsufficientDataError, match="none of the scored events"):
        fit_ratings(np.full((30, len(FEATURES)), np.nan), np.full(30, 5.0))


def test_a_criterion_missing_everywhere_is_left_out_and_nan_counts_at_the_median() -> None:
    rng = np.random.default_rng(2)
    x = draw(rng, 40)
    x[:, FEATURES.index("clunk_ms2")] = np.nan  # e.g. derived from speed: no clunk
    x[3, 0] = np.nan
    model = fit_ratings(x, rule(np.nan_to_num(x)))
    assert "clunk_ms2" not in model.features and len(model.features) == len(FEATURES) - 1
    assert model.score({"shuffle_pp_ms2": None, "kick_ms2": 0.5}) is not None
    assert model.score({}) is None


def test_the_model_round_trips_with_its_version_and_an_edit_is_refused(
        fitted: tuple[RatingModel, np.random.Generator]) -> None:
    model, _ = fitted
    data = json.loads(json.dumps(model.to_dict()))
    again = RatingModel.from_dict(data)
    assert again.version == model.version and again == model
    data["intercept"] += 1.0
    with pytest.raises(InputError, match="does not match its content") as info:
        RatingModel.from_dict(data)
    assert info.value.code == "ratings_model"
    with pytest.raises(InputError, match="not a lashscope rating model"):
        RatingModel.from_dict({"format": 99})


def test_apply_adds_scores_only_where_there_are_criteria(fitted: tuple[RatingModel, np.random.Generator]) -> None:
    model, _ = fitted
    doc = {"summary": {}, "metrics": [
        {"event_index": 0, "drivability": {"measured": {"shuffle_pp_ms2": 0.4, "kick_ms2": 0.2, "max_jerk_ms3": 20.0,
                                                        "clunk_ms2": 0.05, "response_delay_s": 0.1,
                                                        "vdv_ms175": 1.0}}},
        {"event_index": 1, "drivability": {"measured": {"shuffle_pp_ms2": 2.4, "kick_ms2": 1.4, "max_jerk_ms3": 85.0,
                                                        "clunk_ms2": 0.35, "response_delay_s": 0.28,
                                                        "vdv_ms175": 1.9}}},
        {"event_index": 2, "drivability": None},
    ]}
    apply_ratings(doc, model)
    gentle, harsh = (doc["metrics"][i]["drivability"]["rating"] for i in (0, 1))
    assert gentle["score"] > harsh["score"] + 3 and gentle["model"] == model.version
    assert doc["metrics"][2]["drivability"] is None
    assert doc["summary"]["rating"]["events"] == 2 and doc["summary"]["rating"]["cv_rms"] == model.cv_rms
