"""Held-out scores of a model and the statistics the decision rests on.

Residuals are weighted by the model-free noise variance of each sample (see :mod:`.noise`), so a
weighted sum of squares (``chi2``) of ``n`` samples that only contain noise is about ``n``. For a
set of held-out events and two models (baseline ``b``, candidate ``c``):

- ``shrink = 1 - chi2_c / chi2_b`` -- the plain relative reduction of the residual energy;
- ``explained = (chi2_b - chi2_c) / (chi2_b - n)`` -- the share of the residual *above the noise
  floor* that the candidate removes; ``1 - explained`` is what is left unexplained;
- intervals by resampling held-out events with replacement (events, not samples, are the
  independent units: residuals inside an event are correlated).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from app.serial import Serial, rule

FloatArray = npt.NDArray[np.float64]

PHASES: tuple[str, ...] = ("pre_event", "gap_traverse", "impact", "oscillation", "steady")
BANDS: tuple[tuple[str, float, float], ...] = (
    ("0-2Hz", 0.0, 2.0),
    ("2-12Hz", 2.0, 12.0),
    ("12-25Hz", 12.0, 25.0),
    (">25Hz", 25.0, float("inf")),
)
BAND_NAMES: tuple[str, ...] = tuple(b[0] for b in BANDS)


@dataclass(frozen=True)
class EventScore:
    """Weighted residual energy of one model on one event.

    Attributes
    ----------
    index : event index.
    chi2 : weighted sum of squared residuals (noise-variance units).
    n : number of samples (the chi2 expected from noise alone).
    sse_rpm2 : unweighted sum of squared residuals (rpm^2).
    phase_chi2, phase_n : chi2 and sample count per phase (keys of :data:`PHASES`).
    band_energy : unweighted residual energy per frequency band (rpm^2, Parseval-normalised).
    """

    index: int
    chi2: float
    n: int
    sse_rpm2: float
    phase_chi2: dict[str, float]
    phase_n: dict[str, int]
    band_energy: dict[str, float]


ROUNDED = rule(convert=float, digits=4, nonfinite=math.nan)  # an interval's figures: 4 digits, NaN if not finite


@dataclass(frozen=True)
class Interval(Serial):
    value: float = field(metadata=ROUNDED)
    lo: float = field(metadata=ROUNDED)
    hi: float = field(metadata=ROUNDED)


def resample_indices(n_events: int, n_boot: int, seed: int) -> npt.NDArray[np.int64]:
    """(n_boot, n_events) bootstrap draws of event positions, fixed by ``seed``."""
    rng = np.random.default_rng(seed)
    return rng.integers(0, n_events, size=(n_boot, n_events))


def _quantiles(samples: FloatArray, level: float) -> tuple[float, float]:
    a = (1.0 - level) / 2.0
    finite = samples[np.isfinite(samples)]
    if finite.size == 0:
        return float("nan"), float("nan")
    lo, hi = np.quantile(finite, [a, 1.0 - a])
    return float(lo), float(hi)


def shrink_interval(base: FloatArray, cand: FloatArray, draws: npt.NDArray[np.int64], level: float = 0.9) -> Interval:
    """``1 - sum(cand) / sum(base)`` with a bootstrap interval over events."""
    value = 1.0 - float(cand.sum()) / max(float(base.sum()), 1e-300)
    b = base[draws].sum(axis=1)
    c = cand[draws].sum(axis=1)
    boot = 1.0 - c / np.maximum(b, 1e-300)
    lo, hi = _quantiles(boot, level)
    return Interval(value, lo, hi)


def explained_interval(
    base: FloatArray, cand: FloatArray, n: FloatArray, draws: npt.NDArray[np.int64], level: float = 0.9
) -> Interval:
    """Share of the residual above the noise floor removed: ``(b - c) / (b - n)``, with interval.

    When the baseline is not above the noise floor in a resample, that resample says nothing
    about the candidate and counts as 0 explained.
    """

    def frac(b: FloatArray | float, c: FloatArray | float, nn: FloatArray | float) -> FloatArray:
        b_a, c_a, n_a = np.asarray(b, float), np.asarray(c, float), np.asarray(nn, float)
        excess = b_a - n_a
        out = np.where(excess > 0, (b_a - c_a) / np.where(excess > 0, excess, 1.0), 0.0)
        return np.asarray(out, dtype=np.float64)

    value = float(frac(base.sum(), cand.sum(), n.sum()))
    boot = frac(base[draws].sum(axis=1), cand[draws].sum(axis=1), n[draws].sum(axis=1))
    lo, hi = _quantiles(boot, level)
    return Interval(value, lo, hi)


def paired_better_probability(first: FloatArray, second: FloatArray, draws: npt.NDArray[np.int64]) -> float:
    """Bootstrap probability that ``first`` has the lower total (events resampled jointly)."""
    d = (second - first)[draws].sum(axis=1)
    return float(np.mean(d > 0))
