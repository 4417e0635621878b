"""Identification before attribution: is the vehicle file off, and what base do the candidates start from?

A data sheet that is off (a softer half-shaft, a heavier car, more lash) leaves a gap that an
unmodelled effect can mimic convincingly: a soft mount lowers the shuffle mode like a soft shaft.
So once the file's vehicle shows a significant gap, its base parameters are identified on the
calibration events (:func:`app.identify.fit.identify_events`) and the identified vehicle is
scored on the held-out events against the file's, like a candidate (:func:`.decide.score_candidate`):

- a base parameter resting on its prior bound: the file is further off than the priors allow, and
  nothing is attributed -- ``base_parameters``, "identify the vehicle first", naming the parameter;
- identified parameters that differ from the file (:attr:`Identification.named`) and a significant
  held-out improvement: when no gap is left (less than :data:`LEFT_GAP` times the noise floor, or
  less than :data:`LEFT_SHARE` of the gap), ``base_parameters`` ("your data sheet is off", with the
  values and intervals); otherwise the identified vehicle becomes the base every candidate effect
  is fitted on, so that an effect is named only for what the identified base cannot explain;
- no parameter named, but the log chose the other contact law (:mod:`app.identify.form`) with a
  significant held-out improvement: the identified vehicle becomes the base, and the candidates
  decide on it (the law is model form, not a data sheet that is off);
- anything else: the file's vehicle stays the base (the identification is reported).

Whichever base the candidates start from, an effect refitted jointly with the base parameters is named only
if it beats the base alone refitted from that joint fit (:func:`base_alone`, :func:`effect_not_needed`), and a
second effect only beside the first refitted so (``select``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from app.analysis.diagnosis.calibrate import Bounds, FitResult, fit
from app.analysis.diagnosis.decide import CandidateScore, Decision, DecisionRules, gap_ratio, has_gap
from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.partners import PartnerScreen
from app.analysis.diagnosis.score import Interval
from app.analysis.diagnosis.split import Split
from app.identify.base import BASE_EFFECTS, BASE_NAMES
from app.identify.fit import Identification, off_the_gain_bound
from sim import Vehicle
from sim.effects import get_effect

BASE_ID = "base_parameters"
LEFT_GAP = 3.0  # residual-to-noise ratio an identified vehicle must leave for an effect to be looked for on top
# (a base identified at a high signal-to-noise ratio leaves a little of its own model form, which an effect with
# a stiffness of its own -- a mount, a progressive shaft -- then "explains": 1.8x after a 3500x gap)
LEFT_SHARE = 0.05  # ... and at least this share of the gap above the noise floor (its interval's lower end): a 1 kHz
# log whose identified vehicle took 1150x the noise floor to 7.7x leaves its own model form, not an effect
JOINT_PASSES_PER_PARAM = 8  # the joint refit starts at the identified values and the single fit's


@dataclass(frozen=True)
class Rebase:
    """What the identification means for the diagnosis.

    Attributes
    ----------
    stop : a decision to return at once (the data sheet alone explains the gap, or is beyond its priors).
    use : the identified vehicle is the base for the candidates.
    """

    stop: Decision | None
    use: bool
    note: str


def base_items(ident: Identification) -> list[dict[str, Any]]:
    """The named base parameters as the report lists them (ratios to the file's values, with intervals)."""
    return [{"name": p.name, "label": p.label, "ratio": round(p.value / p.nominal, 4),
             "lo": round(p.lo / p.nominal, 4), "hi": round(p.hi / p.nominal, 4), "value": round(p.value, 6),
             "nominal": round(p.nominal, 6), "unit": p.unit}
            for p in ident.params.values() if p.named and p.nominal]


def form_changed(ident: Identification) -> bool:
    """Whether the log chose the other contact law than the file's (:mod:`app.identify.form`)."""
    return bool(ident.form and ident.form.get("changed"))


def sentence(ident: Identification) -> str:
    """"torsional stiffness at the motor 0.70x nominal [0.66, 0.75] (...); vehicle mass ..." for the named ones,
    and the contact law where the log chose another than the file's."""
    parts = [ident.params[k].describe() for k in ident.named]
    if form_changed(ident) and ident.form is not None:
        parts.append(f"contact damping {ident.form['contact_damping']} (the file's law {ident.form['file']} fits the "
                     "impacts worse)")
    return "; ".join(parts)


def judge(ident: Identification, score: CandidateScore, n_heldout: Any, draws: Any, rules: DecisionRules,
          nominal_gap: Any) -> Rebase:
    """The outcome of identifying first (see the module docstring)."""
    # a base parameter on its prior bound (the torque gain is a nuisance: on its bound it stands in for an input
    # effect -- a lag -- as often as for a wrong file, and the candidates judge that)
    bound = [p for k, p in ident.params.items() if k in BASE_NAMES and p.identified and p.at_bound]
    if bound:
        names = ", ".join(f"{p.label} (ratio {p.ratio:.2f} to the file's)" for p in bound)
        reason = (f"identify the vehicle first: {names} is held by the bound of its prior (it rests on it, or its 90 % "
                  "interval reaches it), so the file is further off than an identification of this log can say, or "
                  "the model cannot place it on this log; no unmodelled effect is attributed until the vehicle file is "
                  "corrected")
        return Rebase(Decision(BASE_ID, reason=reason, gap_ratio=nominal_gap,
                               details={"base_parameters": base_items(ident), "identify_first": True,
                                        "at_bound": [p.name for p in bound]}), False, reason)
    if not score.significant or not (ident.named or form_changed(ident)):
        why = ("no base parameter differs from the file beyond its interval" if not ident.named else
               f"the identified base does not improve the held-out events significantly (explained share "
               f"{100 * score.explained.value:.0f} % [{100 * score.explained.lo:.0f}, {100 * score.explained.hi:.0f}])")
        return Rebase(None, False, f"identification: {why}; the file's vehicle stays the base")
    left = gap_ratio(score.chi2, n_heldout, draws, rules.level)
    if not ident.named:  # the contact law alone: model form, not a data sheet that is off; the candidates decide on it
        return Rebase(None, True, f"identification: {sentence(ident)}; the candidates are fitted on the identified "
                                  f"vehicle (held-out residual {left.value:.2f}x the noise floor left)")
    if not has_gap(left, rules) or left.value < LEFT_GAP or score.explained.lo >= 1.0 - LEFT_SHARE:
        reason = (f"the vehicle file is off, and that explains the gap: {sentence(ident)}. With the identified "
                  f"values the held-out residual is {left.value:.2f}x the noise floor (from {nominal_gap.value:.2f}x): "
                  "no unmodelled effect is needed")
        return Rebase(Decision(BASE_ID, reason=reason, gap_ratio=nominal_gap, best=score,
                               details={"base_parameters": base_items(ident), "identify_first": False}),
                      False, reason)
    return Rebase(None, True, f"identification: {sentence(ident)}; the candidates are fitted on the identified "
                              f"vehicle (held-out residual {left.value:.2f}x the noise floor left)")


MIMIC_SHARE = 0.5  # an effect that removes this share of the file's calibration residual above the noise, to first
# order, is named as one the data sheet's error could be mistaken for


def mimicked_by(decision: Decision, screen: Sequence[PartnerScreen], baseline: FitResult) -> Decision:
    """``decision`` (``base_parameters``: the file's error explains the gap) with the candidate effects that would
    change the log alike on a right data sheet, to first order (``screen``: their linearised gains on the file's
    vehicle against its ``baseline``): a soft mount lowers the shuffle mode like a soft shaft. Nothing is
    attributed; the report says what to rule out before correcting the file (``details.mimicked_by``)."""
    excess = max(baseline.chi2 - baseline.n, 1.0)
    alike = [(s.id, min(s.gain / excess, 1.0)) for s in screen if s.gain >= MIMIC_SHARE * excess]
    if not alike:
        return decision
    names = ", ".join(f"{cid} would remove {100 * share:.0f} %" for cid, share in alike)
    reason = (f"{decision.reason}. On a right data sheet an unmodelled effect would change the log alike, to first "
              f"order: {names} of the file's residual above the noise floor. Where the data sheet is known to be "
              "right, rule that out before correcting it")
    return replace(decision, reason=reason, details={
        **decision.details, "mimicked_by": [{"effect": cid, "linear_share": round(share, 4)} for cid, share in alike]})


def joint_with_base(nominal: Vehicle, ident: Identification, events: Sequence[DiagEvent], split: Split, cid: str,
                    single: FitResult, bounds: Bounds, model: str,
                    from_file: tuple[FitResult, Sequence[dict[str, float]]] | None = None,
                    single_on_file: bool = False) -> FitResult | None:
    """Effect ``cid`` and the identified base parameters fitted together on the file's vehicle.

    The total lash is left out next to ``backlash`` (both set the gaps). None when no base parameter is left.
    Refined from each side of the ridge along which an effect and a base parameter trade (a tyre's relaxation
    and the shaft's stiffness), and the better refinement on the calibration events kept:

    - the identified side: the identified base values with the effect at ``single``'s values;
    - the file's side, where there is one: the file's base values with the effect at ``single``'s values when
      ``single`` was fitted on the file's vehicle (``single_on_file``: the single fit is then itself a point of the
      joint model), and at each start of ``from_file`` (the file's baseline fit and the effect's start values from
      its linearised screen on the file's vehicle), refined from whichever of these fits best.

    The start that fits better before refinement is not always the side whose refinement does: on a long drive
    with a tyre's slip a joint fit refined from the identified side stopped at 8x the noise floor with the
    stiffness at 0.68x, and from the file's side reached the noise floor with it at 1.05x.

    A refinement kept with the torque gain on its bound is refined again along the gain-mass ridge
    (:func:`app.identify.fit.off_the_gain_bound`).
    """
    names = [k for k in ident.ratios if not (k == "lash" and cid == "backlash")]
    if not names or cid not in single.values:
        return None
    effects = (*(BASE_EFFECTS[k] for k in names), get_effect(cid))
    values = {BASE_EFFECTS[k].id: dict(ident.fit.values[BASE_EFFECTS[k].id]) for k in names}
    values[cid] = dict(single.values[cid])
    def refine(start: FitResult, alternatives: Sequence[FitResult] = ()) -> FitResult:
        return fit(nominal, events, split, effects, bounds=bounds, model=model, start=start, screen=False,
                   alternatives=alternatives, passes_per_param=JOINT_PASSES_PER_PARAM)
    ours = refine(FitResult((), single.nuisance, values, 0.0, 0, 0))
    at_file = {BASE_EFFECTS[k].id: BASE_EFFECTS[k].off_values() for k in names}
    theirs = [FitResult((), single.nuisance, {**at_file, cid: dict(single.values[cid])}, 0.0, 0, 0)] \
        if single_on_file else []
    if from_file is not None:
        file_fit, effect_starts = from_file
        theirs += [FitResult((), file_fit.nuisance, {**at_file, cid: dict(st)}, 0.0, 0, 0) for st in effect_starts]
    if theirs:
        other = refine(theirs[0], theirs[1:])
        ours = other if other.chi2 < ours.chi2 else ours
    return off_the_gain_bound(ours, refine)


def nuisance_only(ident: Identification) -> FitResult:
    """The identified fit as a baseline of the identified vehicle (its nuisance values, no effects)."""
    return replace(ident.fit, effects=(), values={}, settings=(), trade_offs=(), residual=None, jac=None)


def base_only(decision: Decision, ident: Identification, score: CandidateScore, nominal_gap: Any) -> Decision:
    """``base_parameters`` when no candidate adds anything significant to the identified vehicle.

    ``decision`` was made on the identified vehicle and found no effect (``none_of_candidates``): the file's
    base parameters are what the log says is wrong, and what the identified vehicle leaves is reported as
    the remainder no candidate explains (model form, or physics outside the library), not attributed.
    """
    left = decision.gap_ratio.value if decision.gap_ratio is not None else float("nan")
    reason = (f"the vehicle file is off: {sentence(ident)}. The identified values remove "
              f"{100 * score.explained.value:.0f} % [{100 * score.explained.lo:.0f}, {100 * score.explained.hi:.0f}] "
              f"of the held-out residual above the noise floor ({nominal_gap.value:.2f}x -> {left:.2f}x); no candidate "
              "effect removes a significant share of what is left, which is not attributed")
    return replace(decision, status=BASE_ID, reason=reason, gap_ratio=nominal_gap, best=score,
                   details={**decision.details, "base_parameters": base_items(ident), "identify_first": False,
                            "residual_to_noise_identified": round(left, 4)})


def with_form(decision: Decision, ident: Identification) -> Decision:
    """``decision``, made on the identified vehicle, saying so where the log chose another contact law than the
    file's (:mod:`app.identify.form`): the reason names the law and ``details.contact_damping`` carries the choice."""
    if not form_changed(ident) or ident.form is None:
        return decision
    law, file = ident.form["contact_damping"], ident.form["file"]
    return replace(decision, reason=f"{decision.reason}. Judged on the vehicle with contact damping {law}, which the "
                                    f"log chose over the file's {file}",
                   details={**decision.details, "contact_damping": ident.form})


def base_trade(decision: Decision, fit: FitResult | None) -> list[tuple[str, str, float]]:
    """The trade-offs of the chosen fit between a parameter of the chosen effect(s) and a base parameter
    (``(effect parameter, base parameter, correlation)``)."""
    if fit is None or decision.status not in ("explained", "partial"):
        return []
    tops = set(decision.top)
    base_ids = {e.id for e in BASE_EFFECTS.values()}
    out = []
    for a, b, r in fit.trade_offs:
        for x, y in ((a, b), (b, a)):
            if x.split(".")[0] in tops and y.split(".")[0] in base_ids:
                out.append((x, y, r))
    return out


def not_separable(decision: Decision, ident: Identification, tangled: Sequence[tuple[str, str, float]],
                  nominal_gap: Any, score: CandidateScore | None = None) -> Decision:
    """``base_parameters`` for a decision whose effect trades off with a base parameter in their joint fit.

    The effect and the data sheet's error then describe the same change of the log (a mount and a softer shaft
    both lower the mode): the data cannot tell them apart, and the file being off is the answer that needs no new
    physics. The effect is reported as what could also explain the remainder, not attributed; the held-out figures
    are the identified base's (``score``), not the effect's."""
    what = "; ".join(f"{x} trades off with {y} (correlation {r:+.2f})" for x, y, r in tangled)
    effect = "+".join(decision.top)
    reason = (f"the vehicle file is off: {sentence(ident)}. {effect} would explain what the identified values leave, "
              f"but in their joint fit {what}: the data cannot tell {effect} from the file's error, so no unmodelled "
              "effect is attributed")
    return replace(decision, status=BASE_ID, top=(), reason=reason, gap_ratio=nominal_gap, best=score,
                   details={**decision.details, "base_parameters": base_items(ident), "identify_first": False,
                            "not_separable": [{"effect_param": x, "base_param": y, "correlation": round(r, 4)}
                                              for x, y, r in tangled]})


def told_apart(decision: Decision, tangled: Sequence[tuple[str, str, float]], p_better: float, gap: float
               ) -> Decision:
    """``decision`` kept although its effect trades off with a base parameter in their joint fit: held-out events
    prefer the effect (fitted with the base) to the identified base alone, with probability ``p_better`` and a
    residual-to-noise gap of ``gap`` -- the file's error cannot stand in for it."""
    what = "; ".join(f"{x} trades off with {y} (correlation {r:+.2f})" for x, y, r in tangled)
    reason = (f"{decision.reason}. In the joint fit {what}, but held-out events prefer {'+'.join(decision.top)} to "
              f"the identified base alone (probability {p_better:.2f}, {gap:.2f}x the noise floor less left): the "
              "file's error does not stand in for it")
    return replace(decision, reason=reason, details={
        **decision.details, "base_trade_off": [{"effect_param": x, "base_param": y, "correlation": round(r, 4)}
                                               for x, y, r in tangled],
        "preferred_to_base": {"probability": round(p_better, 4), "separation": round(gap, 4)}})


def base_alone(nominal: Vehicle, ident: Identification, joint: FitResult, events: Sequence[DiagEvent],
               split: Split, bounds: Bounds, model: str) -> FitResult:
    """The base parameters of ``ident`` alone, refitted on the file's vehicle from a joint fit of an effect and the
    base (:func:`joint_with_base`) with the effect switched off.

    The identification alone can stop in another valley than the joint fit: a torque gain of 0.85 standing in for
    a car 16 % heavier, which the joint fit of a tyre's slip and the base left for the right mass. Started from the
    joint fit's base values (those it left out, the lash beside ``backlash``, from the identification), the base
    alone shows what the effect adds to the file's error once both are fitted at their best; held by the torque
    gain's bound, it is refined again along the gain-mass ridge (:func:`app.identify.fit.off_the_gain_bound`)."""
    names = list(ident.ratios)
    values = {BASE_EFFECTS[k].id: dict(joint.values.get(BASE_EFFECTS[k].id, ident.fit.values[BASE_EFFECTS[k].id]))
              for k in names}
    def refine(start: FitResult) -> FitResult:
        return fit(nominal, events, split, tuple(BASE_EFFECTS[k] for k in names), bounds=bounds, model=model,
                   start=start, screen=False, passes_per_param=JOINT_PASSES_PER_PARAM)
    return off_the_gain_bound(refine(FitResult((), joint.nuisance, values, 0.0, 0, 0)), refine)


def effect_not_needed(decision: Decision, ident: Identification, with_effect: CandidateScore,
                      alone: CandidateScore, n_heldout: Any, nominal_gap: Any, p_better: float, gap: float,
                      share: Interval, rules: DecisionRules) -> Decision:
    """``base_parameters`` for an effect that is not needed beside the base parameters alone, refitted from its joint
    fit (:func:`base_alone`; ``ident``: the identification that refit gives, ``alone``: its held-out score): held-out
    events do not prefer the effect to it (probability ``p_better``, noise-floor ratios ``gap`` apart), or the effect
    does not remove a significant ``share`` of what it leaves above the noise floor. The file's error then explains
    what the effect did, and nothing is attributed. Where that refit names no parameter either, nothing is
    attributed and the answer is ``none_of_candidates``."""
    effect = "+".join(decision.top)
    figures = (f"{effect} fitted with the base parameters leaves {with_effect.noise_ratio(n_heldout):.2f}x the noise "
               f"floor on held-out events, the base parameters alone refitted from that fit with {effect} switched "
               f"off leave {alone.noise_ratio(n_heldout):.2f}x: held-out events prefer {effect} with probability "
               f"{p_better:.2f} and {gap:+.2f}x the noise floor less left (needs {rules.prefer_probability:g} and "
               f"{rules.min_separation:g}), and it removes {100 * share.value:.0f} % [{100 * share.lo:.0f}, "
               f"{100 * share.hi:.0f}] of what the base alone leaves above the noise floor (needs "
               f"{100 * rules.min_explained:.0f} % with the interval above zero)")
    details = {**decision.details, "effect_not_needed": {"effect": effect, "probability": round(p_better, 4),
                                                         "separation": round(gap, 4),
                                                         "share_of_base_remainder": {
                                                             "value": round(share.value, 4), "lo": round(share.lo, 4),
                                                             "hi": round(share.hi, 4)}}}
    if not ident.named:
        return replace(decision, status="none_of_candidates", top=(), best=alone, details=details, reason=(
            f"{figures}; the refitted base differs from the file by less than its intervals and the smallest change "
            "worth naming, so neither the effect nor the file is named"))
    return replace(decision, status=BASE_ID, top=(), best=alone, gap_ratio=nominal_gap, reason=(
        f"the vehicle file is off: {sentence(ident)}. {figures}: the file's error explains the gap, and no "
        "unmodelled effect is attributed"),
        details={**details, "base_parameters": base_items(ident), "identify_first": False})


def with_base(decision: Decision, ident: Identification, nominal_gap: Any = None) -> Decision:
    """``decision`` (made on the identified vehicle) saying which base parameters were corrected first.

    Its residual "before" is the file's vehicle's (``nominal_gap``) when the candidates were fitted on the
    identified one."""
    gap = nominal_gap if nominal_gap is not None else decision.gap_ratio
    items = base_items(ident)
    if not items:
        return replace(decision, gap_ratio=gap)
    reason = f"after identifying the vehicle ({sentence(ident)}): {decision.reason}"
    return replace(decision, reason=reason, gap_ratio=gap, details={**decision.details, "base_parameters": items})
