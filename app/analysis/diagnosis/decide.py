"""The explicit decision: which effect explains the gap, and how confidently.

Inputs are held-out scores only (per-event weighted residual energies, see :mod:`.score`). The
rules, in order (thresholds in :class:`DecisionRules`):

1. ``insufficient_data`` -- fewer than ``min_events_per_side`` calibration or held-out events;
2. ``no_significant_gap`` -- the calibrated baseline's residual is not clearly above the
   model-free noise floor (ratio ``chi2 / n`` below ``min_gap_ratio`` or its bootstrap lower
   bound below ``min_gap_ratio_lo``);
3. ``none_of_candidates`` -- no candidate removes a significant share of the residual above the
   noise floor (share below ``min_explained`` or its interval touching zero, or fewer than half
   the held-out events improved);
4. ``ambiguous`` -- the runner-up is significant too and the data do not prefer the best one
   (paired bootstrap probability below ``prefer_probability`` while the shares differ by less than
   ``ambiguous_margin``): the pair is named;
5. ``explained`` -- the best single effect (or greedy pair) removes at least ``explained_share`` of
   the residual above the noise floor, with the interval's lower end at least
   ``explained_share_lo``, *and* what is left is small: a residual-to-noise ratio of at most
   ``max_left_ratio`` or at most ``max_left_share`` of the original excess; otherwise ``partial``.
   The second condition is what keeps a close look-alike (an output filter standing in for an
   input lag, say) from being called an explanation when the true effect is not in the library: it
   removes most of the gap but leaves a clear, structured remainder.

A share of the residual *above the noise floor* is used instead of a plain shrink: with the true
effect outside the library, a look-alike easily removes 30 % of the raw residual, but it leaves
most of the excess over noise behind.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.score import Interval, explained_interval, paired_better_probability, shrink_interval

FloatArray = npt.NDArray[np.float64]

STATUSES = ("explained", "partial", "ambiguous", "none_of_candidates", "no_significant_gap", "insufficient_data")


@dataclass(frozen=True)
class DecisionRules:
    min_events_per_side: int = 3
    min_gap_ratio: float = 1.5
    min_gap_ratio_lo: float = 1.15
    min_explained: float = 0.25
    min_improved_fraction: float = 0.5
    explained_share: float = 0.7
    explained_share_lo: float = 0.5
    prefer_probability: float = 0.95
    ambiguous_margin: float = 0.15
    pair_gain: float = 0.15
    max_left_ratio: float = 2.0
    max_left_share: float = 0.05
    n_boot: int = 2000
    level: float = 0.9

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class CandidateScore:
    """Held-out score of one candidate (a single effect or a greedy pair).

    Attributes
    ----------
    id : ``"torque_lag"`` or ``"torque_lag+drag"``.
    effects : effect ids.
    chi2 : (n_heldout,) weighted residual energy per held-out event.
    shrink, explained : intervals (see :mod:`.score`).
    improved_fraction : share of held-out events whose residual went down.
    significant : passes rule 3.
    """

    id: str
    effects: tuple[str, ...]
    chi2: FloatArray
    shrink: Interval
    explained: Interval
    improved_fraction: float
    significant: bool


@dataclass(frozen=True)
class Decision:
    status: str
    top: tuple[str, ...] = ()
    confusable: tuple[str, ...] = ()
    reason: str = ""
    gap_ratio: Interval | None = None
    best: CandidateScore | None = None
    details: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "status": self.status,
            "top": list(self.top),
            "confusable": list(self.confusable) or None,
            "reason": self.reason,
            "residual_to_noise_before": self.gap_ratio.to_dict() if self.gap_ratio else None,
        }
        if self.best is not None:
            out["explained_share"] = self.best.explained.to_dict()
            out["heldout_shrink"] = self.best.shrink.to_dict()
        out.update(self.details)
        return out


def bootstrap_draws(n_events: int, rules: DecisionRules, seed: int) -> npt.NDArray[np.int64]:
    rng = np.random.default_rng(seed)
    return rng.integers(0, n_events, size=(rules.n_boot, n_events))


def gap_ratio(base: FloatArray, n: FloatArray, draws: npt.NDArray[np.int64], level: float) -> Interval:
    """Residual-to-noise energy ratio ``sum(chi2) / sum(n)`` with a bootstrap interval."""
    value = float(base.sum() / max(n.sum(), 1.0))
    boot = base[draws].sum(axis=1) / np.maximum(n[draws].sum(axis=1), 1.0)
    a = (1 - level) / 2
    lo, hi = np.quantile(boot, [a, 1 - a])
    return Interval(value, float(lo), float(hi))


def score_candidate(cid: str, effects: tuple[str, ...], base: FloatArray, cand: FloatArray, n: FloatArray,
                    draws: npt.NDArray[np.int64], rules: DecisionRules) -> CandidateScore:
    """Held-out statistics of one candidate against the calibrated baseline."""
    shrink = shrink_interval(base, cand, draws, rules.level)
    expl = explained_interval(base, cand, n, draws, rules.level)
    improved = float(np.mean(cand < base)) if base.size else 0.0
    significant = (expl.value >= rules.min_explained and expl.lo > 0.0
                   and improved >= rules.min_improved_fraction)
    return CandidateScore(cid, effects, cand, shrink, expl, improved, bool(significant))


def decide(
    base: FloatArray,
    n: FloatArray,
    singles: Sequence[CandidateScore],
    pairs: Sequence[CandidateScore],
    draws: npt.NDArray[np.int64],
    rules: DecisionRules,
    n_calibration: int,
) -> Decision:
    """Apply the rules of the module docstring.

    Parameters
    ----------
    base : (h,) baseline chi2 per held-out event.
    n : (h,) sample count per held-out event (the chi2 of pure noise).
    singles : scores of single-effect candidates.
    pairs : scores of greedy pairs (may be empty).
    draws : (B, h) bootstrap event draws shared by all comparisons.
    rules : thresholds.
    n_calibration : number of calibration events.
    """
    n_ho = int(base.size)
    if min(n_ho, n_calibration) < rules.min_events_per_side:
        return Decision("insufficient_data", reason=(
            f"{n_calibration} calibration and {n_ho} held-out events; at least {rules.min_events_per_side} "
            f"usable events are needed on each side"))
    ratio = gap_ratio(base, n, draws, rules.level)
    if ratio.value < rules.min_gap_ratio or ratio.lo < rules.min_gap_ratio_lo:
        return Decision("no_significant_gap", gap_ratio=ratio, reason=(
            f"baseline residual is {ratio.value:.2f}x the noise floor (90 % interval {ratio.lo:.2f}-{ratio.hi:.2f}); "
            f"a gap needs at least {rules.min_gap_ratio:g}x with a lower bound of {rules.min_gap_ratio_lo:g}x"))
    ranked = sorted(singles, key=lambda c: float(c.chi2.sum()))
    sig = [c for c in ranked if c.significant]
    if not sig:
        best_share = ranked[0].explained.value if ranked else 0.0
        return Decision("none_of_candidates", gap_ratio=ratio, best=ranked[0] if ranked else None, reason=(
            f"baseline residual is {ratio.value:.2f}x the noise floor, but no candidate removes a significant share "
            f"of it on held-out events (best: {ranked[0].id if ranked else '-'} {100 * best_share:.0f} %)"))
    best = sig[0]
    if len(sig) > 1:
        second = sig[1]
        p = paired_better_probability(best.chi2, second.chi2, draws)
        if p < rules.prefer_probability and best.explained.value - second.explained.value < rules.ambiguous_margin:
            return Decision("ambiguous", top=(best.id,), confusable=(best.id, second.id), gap_ratio=ratio, best=best,
                            reason=(f"{best.id} and {second.id} explain {100 * best.explained.value:.0f} % and "
                                    f"{100 * second.explained.value:.0f} % of the gap; held-out events prefer "
                                    f"{best.id} with probability {p:.2f} only"),
                            details={"prefer_probability": round(p, 3)})
    chosen = best
    pair_note = ""
    for pair in sorted((q for q in pairs if q.effects[0] == best.id), key=lambda c: float(c.chi2.sum())):
        p = paired_better_probability(pair.chi2, best.chi2, draws)
        if pair.explained.value - best.explained.value >= rules.pair_gain and p >= rules.prefer_probability:
            chosen = pair
            pair_note = f"; adding {pair.effects[1]} explains {100 * pair.explained.value:.0f} % (p = {p:.2f})"
        break
    share = chosen.explained
    left_ratio = float(chosen.chi2.sum() / max(n.sum(), 1.0))
    small_left = left_ratio <= rules.max_left_ratio or 1.0 - share.value <= rules.max_left_share
    if share.value >= rules.explained_share and share.lo >= rules.explained_share_lo and small_left:
        status = "explained"
    else:
        status = "partial"
    reason = (f"{' + '.join(chosen.effects)} removes {100 * share.value:.0f} % of the residual above the noise "
              f"floor on held-out events (90 % interval {100 * share.lo:.0f}-{100 * share.hi:.0f} %), "
              f"{100 * chosen.improved_fraction:.0f} % of events improved{pair_note}; the residual left is "
              f"{left_ratio:.2f}x the noise floor")
    return Decision(status, top=chosen.effects, gap_ratio=ratio, best=chosen, reason=reason)
