r"""Drivability ratings, only where a user's own scores earned them: a monotone model from criteria to 1-10.

Subjective drivability scores (the 1-10 scale of expert drivers, 10 = imperceptible) are not a
physical quantity: a score lashscope computed from criteria without anyone's calibration would
look like an answer and be a guess. So no score is shown until a user fits a model to their own
scored events (``lashscope ratings fit RATINGS.csv``); the fitted model is stored with a version
and applied to later analyses.

**Model** (monotone additive, fitted by non-negative least squares)::

    score = b - sum_j sum_k w_jk * max(0, (x_j - q_jk) / s_j),      w_jk >= 0,  clipped to [1, 10]

``x_j`` the criteria in :data:`FEATURES` (each one a driver feels as worse when it grows), ``q_jk``
knots at the 0, 1/3 and 2/3 quantiles of the scored events, ``s_j`` the criterion's spread. Every
term is non-decreasing in its criterion and the weights are non-negative, so the score can only
fall when a criterion grows: a more violent shuffle is never rated better, however few the events.
A criterion that is NaN in an event counts at the median of the scored events (its term is then
the typical one).

**Error**: ``k``-fold cross-validation (5 folds, events shuffled with a fixed seed): each fold
predicted by a model fitted to the others; ``cv_rms`` is the RMS of those predictions' errors in
score points, stored with the model and shown with every rating. At least :data:`MIN_EVENTS`
scored events are needed.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import nnls

from app.analysis.series import FloatArray
from app.errors import InputError, InsufficientDataError
from app.serial import PLAIN, Serial, computed

FORMAT = 1
FEATURES: tuple[str, ...] = ("shuffle_pp_ms2", "kick_ms2", "max_jerk_ms3", "clunk_ms2", "response_delay_s",
                             "vdv_ms175")
KNOT_QUANTILES = (0.0, 1.0 / 3.0, 2.0 / 3.0)
MIN_EVENTS = 20
FOLDS = 5
SCORE_RANGE = (1.0, 10.0)


@dataclass(frozen=True)
class RatingModel(Serial):
    features: tuple[str, ...]
    knots: tuple[tuple[float, ...], ...]  # per feature, criterion units
    scales: tuple[float, ...]  # per feature
    medians: tuple[float, ...]  # per feature: stands in for a NaN criterion
    weights: tuple[tuple[float, ...], ...]  # per feature and knot, >= 0
    intercept: float
    cv_rms: float  # score points
    events: int
    created_at: str = ""
    format: int = FORMAT

    serial_computed = computed(version=PLAIN)

    @property
    def version(self) -> str:
        """A short content hash: two models with the same fit have the same version."""
        body = json.dumps({k: v for k, v in asdict(self).items() if k != "created_at"}, sort_keys=True)
        return hashlib.sha256(body.encode()).hexdigest()[:12]

    @classmethod
    def from_dict(cls, data: dict[str, Any], where: str = "rating model") -> RatingModel:
        if not isinstance(data, dict) or data.get("format") != FORMAT:
            raise InputError(f"{where}: not a lashscope rating model of format {FORMAT}", code="ratings_model")
        try:
            model = cls(tuple(data["features"]), tuple(tuple(float(x) for x in k) for k in data["knots"]),
                        tuple(float(x) for x in data["scales"]), tuple(float(x) for x in data["medians"]),
                        tuple(tuple(float(x) for x in w) for w in data["weights"]), float(data["intercept"]),
                        float(data["cv_rms"]), int(data["events"]), str(data.get("created_at", "")))
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"{where}: malformed ({exc})", code="ratings_model") from exc
        unknown = set(model.features) - set(FEATURES)
        if unknown or not (len(model.knots) == len(model.scales) == len(model.weights) == len(model.features)):
            raise InputError(f"{where}: malformed (features {sorted(unknown) or model.features})", code="ratings_model")
        if data.get("version") not in (None, model.version):
            raise InputError(f"{where}: its version {data.get('version')} does not match its content "
                             f"({model.version}); the file was edited", code="ratings_model")
        return model

    def predict(self, x: FloatArray) -> FloatArray:
        """Scores of criteria rows ``x`` (n, len(features)), clipped to 1-10."""
        return np.clip(self.intercept - _basis(x, self.knots, self.scales, self.medians) @ _flat(self.weights),
                       *SCORE_RANGE)

    def score(self, criteria: dict[str, float | None]) -> float | None:
        """The score of one event's measured criteria; None when none of the model's criteria is known."""
        row = np.array([[_num(criteria.get(f)) for f in self.features]])
        if not np.isfinite(row).any():
            return None
        return float(self.predict(row)[0])


def _num(v: Any) -> float:
    return float(v) if isinstance(v, int | float) and v is not None and math.isfinite(v) else math.nan


def _flat(weights: tuple[tuple[float, ...], ...]) -> FloatArray:
    return np.array([w for ws in weights for w in ws], dtype=np.float64)


def _basis(x: FloatArray, knots: tuple[tuple[float, ...], ...], scales: tuple[float, ...],
           medians: tuple[float, ...]) -> FloatArray:
    cols = []
    for j, (ks, s) in enumerate(zip(knots, scales, strict=True)):
        xj = np.where(np.isfinite(x[:, j]), x[:, j], medians[j])
        cols += [np.maximum(0.0, (xj - k) / s) for k in ks]
    return np.column_stack(cols) if cols else np.zeros((x.shape[0], 0))


def _fit(x: FloatArray, y: FloatArray, features: tuple[str, ...]) -> tuple[RatingModel, FloatArray]:
    medians = tuple(float(np.nanmedian(x[:, j])) if np.isfinite(x[:, j]).any() else 0.0
                    for j in range(x.shape[1]))
    filled = np.where(np.isfinite(x), x, np.array(medians))
    scales = tuple(float(np.std(filled[:, j])) or 1.0 for j in range(x.shape[1]))
    knots = tuple(tuple(float(np.quantile(filled[:, j], q)) for q in KNOT_QUANTILES) for j in range(x.shape[1]))
    b = _basis(x, knots, scales, medians)
    # intercept free (two non-negative columns of opposite sign), every other term enters with a minus sign
    a = np.column_stack((np.ones(len(y)), -np.ones(len(y)), -b))
    coef, _ = nnls(a, y, maxiter=50 * a.shape[1])
    w = coef[2:]
    weights = tuple(tuple(float(v) for v in w[j * len(KNOT_QUANTILES):(j + 1) * len(KNOT_QUANTILES)])
                    for j in range(len(features)))
    model = RatingModel(features, knots, scales, medians, weights, float(coef[0] - coef[1]), math.nan, len(y))
    return model, model.predict(x)


def fit_ratings(x: FloatArray, scores: FloatArray, features: tuple[str, ...] = FEATURES, *,
                min_events: int = MIN_EVENTS, folds: int = FOLDS, seed: int = 0) -> RatingModel:
    """Fit the monotone model to criteria rows ``x`` (n, len(features)) and scores (n,) in 1-10.

    Raises
    ------
    InsufficientDataError (``ratings_too_few_events``)
        Fewer than ``min_events`` scored events, or a criterion known in none of them.
    InputError (``ratings_score``)
        A score outside 1-10 or not a number.
    """
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(scores, dtype=np.float64)
    if x.ndim != 2 or x.shape != (y.size, len(features)):
        raise InputError(f"ratings: criteria of shape {x.shape} for {y.size} scores and {len(features)} criteria")
    bad = ~(np.isfinite(y) & (y >= SCORE_RANGE[0]) & (y <= SCORE_RANGE[1]))
    if bad.any():
        raise InputError(f"ratings: score {y[bad][0]!r} of scored event {int(np.argmax(bad)) + 1} is not in 1-10",
                         code="ratings_score")
    if y.size < min_events:
        raise InsufficientDataError(f"ratings: {y.size} scored events with criteria; a rating model needs at least "
                                    f"{min_events}", code="ratings_too_few_events")
    known: npt.NDArray[np.bool_] = np.asarray(np.isfinite(x).any(axis=0), dtype=bool)
    if not known.any():
        raise InsufficientDataError("ratings: none of the scored events has a drivability criterion",
                                    code="ratings_too_few_events")
    keep = tuple(f for f, k in zip(features, [bool(v) for v in known], strict=True) if k)
    x = x[:, known]
    order = np.random.default_rng(seed).permutation(y.size)
    pred = np.empty(y.size)
    for fold in np.array_split(order, folds):
        train = np.setdiff1d(order, fold)
        m, _ = _fit(x[train], y[train], keep)
        pred[fold] = m.predict(x[fold])
    cv = float(np.sqrt(np.mean((pred - y) ** 2)))
    model, _ = _fit(x, y, keep)
    return RatingModel(model.features, model.knots, model.scales, model.medians, model.weights, model.intercept,
                       cv, int(y.size), datetime.now(UTC).isoformat(timespec="seconds"))


def apply_ratings(doc: dict[str, Any], model: RatingModel) -> None:
    """Add the model's score to every event of an analysis document that has measured criteria, and a summary.

    ``metrics[i]["drivability"]["rating"]`` and ``summary["rating"]`` (median over events, the model's
    version and cross-validated error). Nothing is added for events without criteria.
    """
    scores = []
    for m in doc.get("metrics", []):
        feel = m.get("drivability")
        if not feel:
            continue
        s = model.score(feel.get("measured") or {})
        feel["rating"] = None if s is None else {"score": s, "model": model.version, "cv_rms": model.cv_rms}
        if s is not None:
            scores.append(s)
    if scores:
        doc.setdefault("summary", {})["rating"] = {"median": float(np.median(scores)), "events": len(scores),
                                                   "model": model.version, "cv_rms": model.cv_rms}
