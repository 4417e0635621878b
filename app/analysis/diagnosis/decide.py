"""The explicit decision: which effect explains the gap, and how confidently.

Inputs are held-out scores only (per-event weighted residual energies, see :mod:`.score`, and the
remainder statistics of :mod:`.structure`). The rules, in order (thresholds in
:class:`DecisionRules`):

(``base_parameters`` -- the vehicle file is off -- is decided before these rules, by
:mod:`.rebase`, when the identified base explains the gap or sits on a prior bound.)

1. ``insufficient_data`` -- fewer than ``min_events_per_side`` calibration or held-out events;
2. ``no_significant_gap`` -- the calibrated baseline's residual is not clearly above the
   model-free noise floor (ratio ``chi2 / n`` below ``min_gap_ratio`` or its bootstrap lower
   bound below ``min_gap_ratio_lo``), or it is only above it because of one event: a held-out
   event carrying more than ``max_event_share`` of the residual above the noise floor
   (:func:`dominant_event`; a logger that buffered frames through one reversal, a wheel that
   spun once) does not make a gap alone, the ratio without it must reach ``min_gap_ratio`` too;
3. ``none_of_candidates`` -- no candidate removes a significant share of the residual above the
   noise floor (share below ``min_explained`` or its interval touching zero, or fewer than half
   the held-out events improved);
4. ``ambiguous`` -- the runner-up is significant too and the held-out data do not separate the
   two: the best is *preferred* only when a paired event bootstrap puts it ahead with probability
   at least ``prefer_probability`` **and** its remainder-to-noise ratio is lower by at least
   ``min_separation`` (a difference smaller than the scatter of the noise floor itself is no
   evidence, however consistent: an input lag and an output filter on a driveline whose gap
   phase the data do not resolve differ only by discretisation, on every event alike). The
   pair is named;
5. ``explained`` -- the best single effect (or greedy pair) removes at least ``explained_share`` of
   the residual above the noise floor, with the interval's lower end at least
   ``explained_share_lo``, *and* what it leaves is indistinguishable from noise: none of the
   remainder statistics of :mod:`.structure` (overall, lash-traverse + impact, event-locked) is
   above the noise floor by the same test that makes a baseline residual a gap (value above
   ``min_gap_ratio`` with lower bound above ``min_gap_ratio_lo``). Otherwise ``partial``: the
   effect is attributed, and the reason says which remainder is left and how large.

A share of the residual *above the noise floor* is used instead of a plain shrink: with the true
effect outside the library, a look-alike easily removes 30 % of the raw residual, but it leaves
most of the excess over noise behind. And a share alone is not enough either: 5 % of a gap that
is 200x the noise is still 10x the noise -- a look-alike (an output filter standing in for an
input lag) removes most of a large gap and leaves a clear, structured remainder, which rule 5
reports as ``partial``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.orders import OrderTone
from app.analysis.diagnosis.score import Interval, explained_interval, paired_better_probability, shrink_interval
from app.analysis.diagnosis.structure import Remainder, RemainderTest, remainder_test, totals_only
from app.serial import Serial, lists, rule

FloatArray = npt.NDArray[np.float64]

STATUSES = ("explained", "partial", "ambiguous", "none_of_candidates", "no_significant_gap", "insufficient_data",
            "base_parameters")


@dataclass(frozen=True)
class DecisionRules(Serial):
    min_events_per_side: int = 3
    min_gap_ratio: float = 1.5
    min_gap_ratio_lo: float = 1.15
    min_explained: float = 0.25
    min_improved_fraction: float = 0.5
    explained_share: float = 0.7
    explained_share_lo: float = 0.5
    prefer_probability: float = 0.95
    min_separation: float = 0.1
    pair_gain: float = 0.15
    # a second effect kept for the structured remainder alone must remove at least this share of that
    # remainder's excess over noise (and take it below the single's own event scatter, see _with_partner): a
    # smaller gain is what a second effect's extra freedom buys on model-form residue
    pair_remainder_gain: float = 0.4
    n_boot: int = 2000
    level: float = 0.9
    max_event_share: float = 0.5  # one held-out event with more of the baseline's excess does not decide rule 2


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
    remainder : remainder-to-noise statistics of what the candidate leaves (None: not computed).
    without_second : pairs only: (n_heldout,) chi2 of the pair's fit with its second effect off --
        the first effect at the values the pair fit gave it.
    entangled : pairs only: ``(first-effect parameter, second-effect parameter, correlation)`` when the
        pair's fit cannot separate them (:func:`.calibrate.trade_offs`): the second effect then changes
        what the first one already can, and is not named on its own.
    relieves : pairs only: ``(first-effect parameter, its value alone, its value in the pair)`` when the
        single fit left it on a prior bound and the pair's fit moves it inside: the second effect then
        stands in for what the first effect's law cannot reach within its prior, and is not named on
        its own either.
    """

    id: str
    effects: tuple[str, ...]
    chi2: FloatArray
    shrink: Interval
    explained: Interval
    improved_fraction: float
    significant: bool
    remainder: RemainderTest | None = None
    without_second: FloatArray | None = None  # pairs: chi2 per event with the second effect switched off
    entangled: tuple[str, str, float] | None = None  # pairs: a first-effect parameter the second trades off with
    relieves: tuple[str, float, float] | None = None  # pairs: a first-effect parameter the pair takes off a bound

    def noise_ratio(self, n: FloatArray) -> float:
        """Remaining residual-to-noise ratio ``sum(chi2) / sum(n)``."""
        return float(self.chi2.sum() / max(float(n.sum()), 1.0))


@dataclass(frozen=True)
class Decision(Serial):
    status: str
    top: tuple[str, ...] = field(default=(), metadata=rule(convert=lists))
    confusable: tuple[str, ...] = field(default=(), metadata=rule(convert=lists, falsy_none=True))
    reason: str = ""
    gap_ratio: Interval | None = field(default=None, metadata=rule(key="residual_to_noise_before"))
    best: CandidateScore | None = field(default=None, metadata=rule(convert=lambda b: {} if b is None else {
        "explained_share": b.explained, "heldout_shrink": b.shrink}, flatten=True))
    details: dict[str, Any] = field(default_factory=dict, metadata=rule(flatten=True))


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


def has_gap(ratio: Interval, rules: DecisionRules) -> bool:
    """Rule 2: whether the baseline's residual-to-noise ratio is clearly above the noise floor."""
    return bool(ratio.value >= rules.min_gap_ratio and ratio.lo >= rules.min_gap_ratio_lo)


def dominant_event(base: FloatArray, n: FloatArray, rules: DecisionRules) -> tuple[int, float, float] | None:
    """The held-out event carrying more than ``max_event_share`` of the residual above the noise floor:
    ``(its position, its share, residual-to-noise ratio of the others)``; None when no event does or there
    are no more events than ``min_events_per_side``."""
    excess = np.maximum(base - n, 0.0)
    total = float(excess.sum())
    if total <= 0 or base.size <= rules.min_events_per_side:
        return None
    k = int(np.argmax(excess))
    share = float(excess[k]) / total
    if share <= rules.max_event_share:
        return None
    others = np.arange(base.size) != k
    return k, share, float(base[others].sum() / max(float(n[others].sum()), 1.0))


def score_candidate(cid: str, effects: tuple[str, ...], base: FloatArray, cand: FloatArray, n: FloatArray,
                    draws: npt.NDArray[np.int64], rules: DecisionRules,
                    rem: Remainder | None = None) -> CandidateScore:
    """Held-out statistics of one candidate against the calibrated baseline (``rem``: its remainder)."""
    shrink = shrink_interval(base, cand, draws, rules.level)
    expl = explained_interval(base, cand, n, draws, rules.level)
    improved = float(np.mean(cand < base)) if base.size else 0.0
    significant = (expl.value >= rules.min_explained and expl.lo > 0.0
                   and improved >= rules.min_improved_fraction)
    test = remainder_test(rem if rem is not None else totals_only(cand, n), draws, rules.level)
    return CandidateScore(cid, effects, cand, shrink, expl, improved, bool(significant), test)


def separation(best: CandidateScore, other: CandidateScore, n: FloatArray, draws: npt.NDArray[np.int64],
               rules: DecisionRules) -> tuple[bool, float, float]:
    """Whether held-out events prefer ``best`` over ``other`` (rule 4): (preferred, probability, ratio gap)."""
    p = paired_better_probability(best.chi2, other.chi2, draws)
    gap = other.noise_ratio(n) - best.noise_ratio(n)
    return bool(p >= rules.prefer_probability and gap >= rules.min_separation), p, gap


def _left_over(chosen: CandidateScore, n: FloatArray, rules: DecisionRules) -> tuple[list[str], str]:
    """Remainder statistics above noise, and a sentence describing them."""
    t = chosen.remainder
    if t is None:  # built by hand: judge the total only
        t = remainder_test(totals_only(chosen.chi2, n), np.zeros((1, n.size), dtype=np.int64), rules.level)
    above = t.above_noise(rules.min_gap_ratio, rules.min_gap_ratio_lo)
    text = "what is left, as a ratio to the noise floor: " + "; ".join(t.describe())
    if above:
        text += f" -- above noise: {', '.join(above)}"
    return above, text


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
    one = dominant_event(base, n, rules)
    if one is not None and has_gap(ratio, rules) and one[2] < rules.min_gap_ratio:
        return Decision("no_significant_gap", gap_ratio=ratio, details={
            "remainder": remainder_field([], one[2], explained=None)}, reason=(
            f"baseline residual is {ratio.value:.2f}x the noise floor, but one held-out event carries "
            f"{100 * one[1]:.0f} % of the residual above it; without that event it is {one[2]:.2f}x: a gap needs "
            f"at least {rules.min_gap_ratio:g}x without any single event"))
    if not has_gap(ratio, rules):
        return Decision("no_significant_gap", gap_ratio=ratio, details={
            "remainder": remainder_field([], ratio.value, explained=None)}, reason=(
            f"baseline residual is {ratio.value:.2f}x the noise floor (90 % interval {ratio.lo:.2f}-{ratio.hi:.2f}); "
            f"a gap needs at least {rules.min_gap_ratio:g}x with a lower bound of {rules.min_gap_ratio_lo:g}x"))
    ranked = sorted(singles, key=lambda c: float(c.chi2.sum()))
    sig = [c for c in ranked if c.significant]
    if not sig:
        best_share = ranked[0].explained.value if ranked else 0.0
        return Decision("none_of_candidates", gap_ratio=ratio, best=ranked[0] if ranked else None, reason=(
            f"baseline residual is {ratio.value:.2f}x the noise floor, but no candidate removes a significant share "
            f"of it on held-out events (best: {ranked[0].id if ranked else '-'}, explained share "
            f"{100 * best_share:.0f} %{OVER_FULL if best_share > 1.0 else ''}): the remainder is structure no "
            "candidate in the library explains"),
            details={"remainder": remainder_field(["overall"], ratio.value, explained=False)})
    best = sig[0]
    joint_note = ""
    if len(sig) > 1:
        second = sig[1]
        preferred, p, gap = separation(best, second, n, draws, rules)
        joint = None if preferred else _both(base, best, second, pairs, n, draws, rules)
        if joint is not None:  # the two are not rivals but both present: their pair beats each of them
            joint_note = (f"; {best.id} and {second.id} alone are not separated by the held-out events "
                          f"(p = {p:.2f}), the joint fit of {' and '.join(joint.effects)} is preferred to each "
                          f"and lowers the remainder from {best.noise_ratio(n):.2f}x to "
                          f"{joint.noise_ratio(n):.2f}x the noise floor")
            best = joint
        elif not preferred:
            return Decision("ambiguous", top=(best.id,), confusable=(best.id, second.id), gap_ratio=ratio, best=best,
                            reason=(f"{best.id} and {second.id} explain {100 * best.explained.value:.0f} % and "
                                    f"{100 * second.explained.value:.0f} % of the gap and leave "
                                    f"{best.noise_ratio(n):.2f}x and {second.noise_ratio(n):.2f}x the noise floor; "
                                    f"held-out events prefer "
                                    f"{best.id} with probability {p:.2f} (needs {rules.prefer_probability:g} and a "
                                    f"ratio gap of at least {rules.min_separation:g}): the data do not separate them"),
                            details={"prefer_probability": round(p, 3), "separation": round(gap, 4),
                                     "remainder": remainder_field(_left_over(best, n, rules)[0], best.noise_ratio(n),
                                                                  explained=False)})
    chosen, pair_note, unresolved = ((best, joint_note, ()) if len(best.effects) > 1
                                     else _with_partner(base, best, pairs, n, draws, rules))
    share = chosen.explained
    above, left_text = _left_over(chosen, n, rules)
    if share.value >= rules.explained_share and share.lo >= rules.explained_share_lo and not above:
        status = "explained"
    else:
        status = "partial"
    reason = (f"{' + '.join(chosen.effects)}: {_figures(chosen)}, {100 * chosen.improved_fraction:.0f} % of events "
              f"improved{pair_note}; {left_text}")
    details: dict[str, Any] = {}
    if chosen.remainder is not None:
        details["remainder_to_noise"] = chosen.remainder.to_dict()
        details["remainder_above_noise"] = above
    details["remainder"] = remainder_field(above, chosen.noise_ratio(n), explained=not above)
    if unresolved:
        details["second_unresolved"] = list(unresolved)
    if above:
        reason += (f". The remainder is structured ({', '.join(above)}) and no candidate in the library "
                   f"explains it")
    return Decision(status, top=chosen.effects, gap_ratio=ratio, best=chosen, reason=reason, details=details)


OVER_FULL = " (above 100 %: the fit also removed part of the noise floor)"

# an input lag and an output filter: on a driveline that is otherwise linear they are the same operator, and only the
# lash traverse and the impact tell them apart (sim/effects/speed_sensor.py)
LAG_EFFECTS = ("torque_lag", "speed_sensor")


def lags_apart(decision: Decision, traverse_samples: float, min_samples: float,
               candidates: Sequence[str]) -> Decision:
    """``decision``, or "ambiguous" between the two lags when the log cannot tell them apart.

    Where the lash traverse spans fewer than ``min_samples`` speed samples in the median event, the phases
    that separate a torque lag from a speed filter fall between samples: the offset takes the delay and the
    base model's damping the rest, so a single lag named alone is a guess between the two (on the independent
    generator's chain car at 20-50 Hz, real torque lags read as speed filters). The decision then names the
    best one with the other as confusable, as when held-out events do not separate two candidates.
    """
    if (traverse_samples >= min_samples or decision.status not in ("explained", "partial")
            or len(decision.top) != 1 or decision.top[0] not in LAG_EFFECTS
            or not all(e in candidates for e in LAG_EFFECTS)):
        return decision
    top = decision.top[0]
    other = next(e for e in LAG_EFFECTS if e != top)
    return replace(decision, status="ambiguous", confusable=(top, other), reason=(
        f"{decision.reason}. The lash traverse spans {traverse_samples:g} speed samples in the median event (under "
        f"{min_samples:g}): a lag of the torque ({LAG_EFFECTS[0]}) and a filter of the speed ({LAG_EFFECTS[1]}) "
        f"differ only there, so {top} is not told from {other} by this log"),
        details={**decision.details, "lags_unresolved": {"traverse_samples": traverse_samples,
                                                          "min_samples": min_samples}})


OFFSET_AT_BOUND = "nuisance.offset_s"  # FitResult.at_bound's name of the torque-to-speed time offset on its bound


def timing_unresolved(decision: Decision, fit_at_bound: Sequence[str], offset_s: float) -> Decision:
    """``decision``, or no attribution when the chosen effect's fit rests the torque-to-speed time offset on its
    bound (``fit_at_bound``: that fit's ``at_bound``; ``offset_s``: its offset).

    The offset is a nuisance, bounded to what a logger's timing can be (``calibrate.OFFSET_MIN_S``, or two sample
    periods). A fit that needs it on the bound has not aligned the logged torque and speed: the timing itself is
    what the log shows, and an effect fitted under that misalignment explains a shape it was not made for (on the
    independent generator, a 21 ms speed filter with 7 ms delay at 100 Hz read as a mount plus backlash, while the
    offset sat at +20 ms in every fit but the torque lag's). Right answers on the benchmarks bring the offset inside
    its bound, or name a lag or filter (:data:`LAG_EFFECTS`), which models a delay itself: a torque lag of 20 ms on a
    right data sheet was fitted with the offset on its bound beside it, and named rightly. So where no effect of the
    answer models a delay, nothing is attributed, and the reason names the offset. (The rule also withdraws half
    answers: two drives whose truth pairs a torque lag with tyre slip read ``partial tyre_slip`` with the offset on
    its bound, the lag the offset could not take unnamed; docs/diagnosis.md.) It withdraws a first effect beside a
    lag or a filter not told apart (``details.second_unresolved``) too: that effect was fitted under the misalignment
    the unnamed lag removes (a soft mount beside a speed filter on ``ifinal6``, where the filter was the truth)."""
    if (decision.status not in ("explained", "partial") or OFFSET_AT_BOUND not in fit_at_bound
            or any(e in LAG_EFFECTS for e in decision.top)):
        return decision
    top = " + ".join(decision.top)
    return Decision("none_of_candidates", gap_ratio=decision.gap_ratio, best=decision.best, reason=(
        f"{top} would explain part of the gap, but only with the time offset between the logged torque and speed on "
        f"its bound ({1000 * offset_s:+.1f} ms): no candidate aligns the two, so the timing itself is unexplained "
        f"(a speed filter or delay, or time stamps, beyond what the library models) and nothing is attributed"),
        details={"would_attribute": list(decision.top), "offset_at_bound_s": offset_s})


def withdrawn_for_timing(decision: Decision) -> bool:
    """Whether ``decision`` is an attribution :func:`timing_unresolved` withdrew (its details carry the offset)."""
    return "offset_at_bound_s" in decision.details


def _figures(c: CandidateScore) -> str:
    """The two held-out figures of a candidate, each under its one name (see :mod:`.score`)."""
    return (f"explained share {100 * c.explained.value:.0f} % [{100 * c.explained.lo:.0f}, "
            f"{100 * c.explained.hi:.0f}] of the residual above the noise floor"
            f"{OVER_FULL if c.explained.value > 1.0 else ''}, held-out shrink "
            f"{100 * c.shrink.value:.0f} % [{100 * c.shrink.lo:.0f}, {100 * c.shrink.hi:.0f}] of the residual energy")


def structured(c: CandidateScore, rules: DecisionRules) -> bool:
    """Whether what ``c`` leaves on held-out events is above noise by any remainder statistic."""
    return bool(c.remainder is not None and c.remainder.above_noise(rules.min_gap_ratio, rules.min_gap_ratio_lo))


def _with_partner(base: FloatArray, best: CandidateScore, pairs: Sequence[CandidateScore], n: FloatArray,
                  draws: npt.NDArray[np.int64], rules: DecisionRules) -> tuple[CandidateScore, str, tuple[str, ...]]:
    """The best single effect, or its best pair when the second effect earns its place on held-out events, with a
    sentence, and the two second effects held-out events do not tell apart (empty unless so).

    It does when the held-out events prefer the pair (paired bootstrap probability at least
    ``prefer_probability``) and either it explains ``pair_gain`` more of the gap, or the single
    effect leaves a structured remainder and the pair removes ``pair_remainder_gain`` of *that* remainder's
    excess over noise (and at least ``min_separation`` of its ratio) -- a faint second effect
    explains little of a large gap but is all that the first one's remainder holds.
    """
    for pair in sorted((q for q in pairs if q.effects[0] == best.id), key=lambda c: float(c.chi2.sum())):
        # judged against the better of the single fit and the pair's own fit with the second effect off:
        # a gain that the first effect alone reaches at the pair's values is a better fit of the first
        # effect, not evidence for the second
        ref = best.chi2
        if pair.without_second is not None and float(pair.without_second.sum()) < float(ref.sum()):
            ref = pair.without_second
        p = paired_better_probability(pair.chi2, ref, draws)
        excess = float(ref.sum() - n.sum())
        base_excess = float(base.sum() - n.sum())
        gain = float(ref.sum() - pair.chi2.sum()) / base_excess if base_excess > 0 else 0.0
        left = float(ref.sum() / max(float(n.sum()), 1.0))
        lower = left - pair.noise_ratio(n)
        of_remainder = lower * float(n.sum()) / excess if excess > 0 else 0.0
        # ... and takes it below what the single's own remainder could be, resampling the events: a second
        # effect that lowers a remainder near the noise floor by less than that scatter is model-form residue
        scatter_lo = best.remainder.overall.lo if best.remainder is not None else left
        for_remainder = (structured(best, rules) and lower >= rules.min_separation
                         and of_remainder >= rules.pair_remainder_gain and pair.noise_ratio(n) < scatter_lo)
        if p >= rules.prefer_probability and (gain >= rules.pair_gain or for_remainder):
            would = (f"; adding {pair.effects[1]} would lower the remainder from {left:.2f}x to "
                     f"{pair.noise_ratio(n):.2f}x the noise floor, but ")
            if pair.entangled is not None:
                a, b, r = pair.entangled
                return best, (f"{would}{b} trades off with {a} (correlation {r:+.2f}): it changes what "
                              f"{best.id} already does, where this effect's law and the vehicle's differ, and "
                              f"is not named on its own"), ()
            if pair.relieves is not None:
                name, alone, inside = pair.relieves
                return best, (f"{would}it takes {name} off its prior bound ({alone:.4g} alone, {inside:.4g} in "
                              f"the pair): it stands in for what {best.id}'s law cannot reach within its prior, "
                              f"and is not named on its own"), ()
            # ... and only if no other second effect does as well on held-out events, or tells the two apart only
            # where the pair leaves a remainder: a torque lag and a speed filter differ in the lash traverse and the
            # impact alone (LAG_EFFECTS), and a pair that leaves those phases above the noise floor does not fit them
            # (beside a tyre's slip with the lash refitted, the filter left 1.17x and the true lag 1.32x overall,
            # 3.3x at the impacts)
            misfit = pair.remainder is not None and "impact" in pair.remainder.above_noise(rules.min_gap_ratio,
                                                                                            rules.min_gap_ratio_lo)
            for rival in (q for q in pairs if q.effects[0] == best.id and q.id != pair.id):
                told, p_rival, gap = separation(pair, rival, n, draws, rules)
                by_impact = misfit and {pair.effects[1], rival.effects[1]} == set(LAG_EFFECTS)
                if told and not by_impact:
                    continue
                why = ("held-out events do not tell the two apart" if not told else
                       "the two differ only in the lash-traverse and impact phases, where the pair leaves "
                       f"{pair.remainder.impact.value:.2f}x the noise floor" if pair.remainder is not None else "")
                return best, (f"{would}adding {rival.effects[1]} lowers it to {rival.noise_ratio(n):.2f}x: {why} "
                              f"(p = {p_rival:.2f}, {gap:+.2f}x the noise floor apart), so neither is named"), \
                    (pair.effects[1], rival.effects[1])
            return pair, (f"; adding {pair.effects[1]} lowers the remainder from {left:.2f}x to "
                          f"{pair.noise_ratio(n):.2f}x the noise floor (p = {p:.2f})"), ()
        break
    return best, "", ()


def _both(base: FloatArray, best: CandidateScore, second: CandidateScore, pairs: Sequence[CandidateScore],
          n: FloatArray, draws: npt.NDArray[np.int64], rules: DecisionRules) -> CandidateScore | None:
    """The best pair holding ``best`` when held-out events prefer it to *each* of the two inseparable singles
    and it explains ``pair_gain`` more of the gap than ``best``: two effects that are both present look alike
    one at a time (each takes up part of the other's signature), and only a joint fit separates them. The
    pair's second effect need not be ``second``: the runner-up may only stand in for part of a third
    effect's signature."""
    base_excess = float(base.sum() - n.sum())
    if base_excess <= 0:
        return None
    for pair in sorted((q for q in pairs if best.id in q.effects), key=lambda c: float(c.chi2.sum())):
        p = min(paired_better_probability(pair.chi2, c.chi2, draws) for c in (best, second))
        gain = float(best.chi2.sum() - pair.chi2.sum()) / base_excess
        if pair.significant and p >= rules.prefer_probability and gain >= rules.pair_gain:
            return pair
        break
    return None


def remainder_field(above: Sequence[str], ratio_to_noise: float, explained: bool | None) -> dict[str, Any]:
    """``decision.remainder``: is what the decision leaves noise, or structure no candidate explains.

    ``explained``: whether the named candidates account for the gap (None: there was no gap).
    """
    if not above:
        return {"status": "noise", "explained_by_candidates": explained, "where": [],
                "ratio_to_noise": round(float(ratio_to_noise), 4)}
    return {"status": "structured", "explained_by_candidates": explained, "where": list(above),
            "ratio_to_noise": round(float(ratio_to_noise), 4)}


def with_tones(decision: Decision, tones: Sequence[OrderTone]) -> Decision:
    """``decision`` with the speed channel's motor-order tones (:mod:`.orders`) named as structured remainder.

    A tone locked to the rotor angle is structure no candidate in the library models (torque ripple, a
    resolver's angle error), so whatever the events say, the remainder is ``structured`` and the status
    is never ``explained``.
    """
    if not tones or decision.status == "insufficient_data":
        return decision
    names = [t.describe() for t in tones]
    old = decision.details.get("remainder") or {}
    where = [*old.get("where", []), *names]
    ratio = float(old.get("ratio_to_noise", 0.0))
    explained = old.get("explained_by_candidates")
    details = {**decision.details, "tones": [t.to_dict() for t in tones],
               "remainder": remainder_field(where, ratio, explained=False if explained else explained)}
    status = "partial" if decision.status == "explained" else decision.status
    reason = (f"{decision.reason}. The speed carries {'a tone' if len(tones) == 1 else 'tones'} locked to the rotor "
              f"angle: {', '.join(names)} (F = {max(t.f_stat for t in tones):.0f} against the blocks' own "
              f"noise): torque ripple or a speed-sensor angle error, which no candidate in the library models")
    return replace(decision, status=status, details=details, reason=reason)
