"""The diagnosis procedure: split, calibrate, fit candidates, greedy pairs, score, decide.

:func:`run_diagnosis` is pure (data in, typed result out) and reports progress through a callback
``progress(fraction, message)``. Order of work, and what sees which events::

    split (frozen, seed + SHA-256)          all events
    baseline fit (nuisance only)            calibration events
    no significant gap: stop                held-out events
    identification of the base parameters   calibration events (app.identify)
    held-out test of the identified base    held-out events: no gap left -> ``base_parameters`` (with
                                            the effects a linearised screen on the file's vehicle says
                                            would change the log alike, ``mimicked_by``);
                                            a base parameter at its prior bound -> ``base_parameters``
                                            ("identify the vehicle first"); otherwise the identified
                                            vehicle is the base every candidate is fitted on
    each candidate: joint fit               calibration events
    scores, localisation                    held-out events (fitted values frozen)
    greedy pairs: best single + partners    fit on calibration, scored on held-out
    the best two, and the best by a screen  calibration events (each effect refitted with the base
    on the file's vehicle: joint refits     parameters, from the identified and the file's values)
    decision                                held-out scores only
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt

from app.analysis.blas_threads import single_blas_thread
from app.analysis.diagnosis.calibrate import Bounds, FitResult, fit, stage_starts
from app.analysis.diagnosis.decide import (
    CandidateScore,
    Decision,
    DecisionRules,
    bootstrap_draws,
    decide,
    gap_ratio,
    has_gap,
    lags_apart,
    score_candidate,
    separation,
    structured,
    timing_unresolved,
    with_tones,
    withdrawn_for_timing,
)
from app.analysis.diagnosis.forward import (
    DiagEvent,
    Prediction,
    prediction,
    simulate_events,
    vehicle_with,
    weighted_residual,
)
from app.analysis.diagnosis.identify import with_identifiability
from app.analysis.diagnosis.localise import (
    MIN_TRAVERSE_SAMPLES,
    PhaseTimes,
    band_energy,
    phase_chi2,
    phase_times,
    uniform,
)
from app.analysis.diagnosis.noise import NoiseFloor
from app.analysis.diagnosis.partners import screen_partners
from app.analysis.diagnosis.rebase import (
    BASE_ID,
    base_alone,
    base_only,
    base_trade,
    effect_not_needed,
    joint_with_base,
    judge,
    mimicked_by,
    not_separable,
    nuisance_only,
    told_apart,
    with_base,
    with_form,
)
from app.analysis.diagnosis.score import EventScore, Interval
from app.analysis.diagnosis.split import STAGE_EVENTS, Split, make_split, restricted, stage_sizes, stratified_order
from app.analysis.diagnosis.structure import remainder
from app.analysis.diagnosis.uncertainty import with_input_uncertainty
from app.errors import InputError, InsufficientDataError, NotIdentifiableError
from app.identify.base import BASE_EFFECTS, BASE_NAMES
from app.identify.fit import FitOptions, Identification, identify_events
from app.identify.fit import refined as identified_with
from sim import Vehicle
from sim.effects import EFFECTS, get_effect

FloatArray = npt.NDArray[np.float64]
Progress = Callable[[float, str], None]
PAIR_PASSES_PER_PARAM = 10  # a pair's refinement starts near its solution (the single fit + the screen's step)
BASE_SHARE_APART = 0.75  # an effect trading off with the base is told apart only if the identified base alone explains
# less than this share of the held-out gap: where the file's error explains most of the gap, an effect with a
# stiffness of its own fits the base's model form (a mount on a 1 kHz drive whose stiffness, mass and lash were off:
# the identified base explained 84 %); a tyre's compliance or a progressive shaft on a correct data sheet, taken in
# part by the identification (58-62 %, with 344-1742x the noise floor left), is real. (Until then: under 50 %, the
# interval's upper end, which on 4 held-out events reached 76 % for the progressive shaft.)
JOINT_REFITS = 2  # best single effects refitted jointly with the identified base parameters
FILE_SCREEN_REFITS = 1  # with an identified base: the best candidate by its linearised gain on the file's vehicle is
# refitted jointly with the base parameters too, from the file's values


@dataclass(frozen=True)
class DiagnosisOptions:
    candidates: tuple[str, ...] = tuple(EFFECTS)
    seed: int = 0
    model: str = "multibody"
    max_pairs: int = 2  # partners tried with the best single effect (the screen's best)
    # a partner is fitted only if, to first order, it removes at least this share of what the best single fit
    # leaves above noise on calibration events (partners.screen_partners), and at least one standard deviation
    # of the chi2 of pure noise (sqrt(2 n)): a pair fit costs up to about 70 simulator passes
    min_partner_gain: float = 0.02
    # model-form tolerance: a residual under this fraction of the local predicted oscillation is no evidence
    # of a missing effect (see uncertainty.input_uncertainty). Off by default: at 0.15 it removed the false
    # attributions on the independent generator's no-effect drives but also hid clean 15 ms torque lags
    # (docs/diagnosis.md, "Model-form tolerance")
    model_form_rel: float = 0.0
    # the sequential design of run_diagnosis (stratified stages of 24, 48, ... events per side, stopped once two
    # stages agree); False: every event in one stage, whatever the drive's length
    sequential: bool = True
    stage_events: int = STAGE_EVENTS  # events per side of the sequential design's first stage
    rules: DecisionRules = field(default_factory=DecisionRules)

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_partner_gain <= 1.0:
            raise InputError(f"min_partner_gain = {self.min_partner_gain}: must be within 0..1 (a share of the "
                             "remainder above noise)")
        if not 0.0 <= self.model_form_rel <= 1.0:
            raise InputError(f"model_form_rel = {self.model_form_rel}: must be within 0..1 (a fraction of the "
                             "predicted oscillation)")
        unknown = [c for c in self.candidates if c not in EFFECTS]
        if unknown:
            raise InputError(f"unknown candidate effects {unknown}; known: {list(EFFECTS)}")
        if len(set(self.candidates)) != len(self.candidates):
            raise InputError(f"candidate effects repeat: {list(self.candidates)}")
        if self.stage_events < self.rules.min_events_per_side:
            raise InputError(f"stage_events = {self.stage_events}: a stage needs at least "
                             f"{self.rules.min_events_per_side} events per side")
        if self.model not in ("multibody", "two_inertia"):
            raise InputError(f"model {self.model!r}: must be 'multibody' or 'two_inertia'")


@dataclass
class Evaluation:
    """A fitted model evaluated on events: per-event scores and predictions."""

    fit: FitResult
    scores: dict[int, EventScore]
    predictions: dict[int, Prediction]

    def chi2(self, indices: Sequence[int]) -> FloatArray:
        return np.array([self.scores[i].chi2 for i in indices], dtype=np.float64)


@dataclass
class DiagnosisResult:
    """Everything the report and the plots need (see :mod:`.report` for the JSON form)."""

    options: DiagnosisOptions
    vehicle_name: str
    split: Split
    noise: NoiseFloor
    events: list[DiagEvent]
    skipped: list[dict[str, object]]
    baseline: Evaluation | None
    candidates: dict[str, Evaluation]
    singles: list[CandidateScore]
    pairs: list[CandidateScore]
    phases: dict[int, PhaseTimes]
    decision: Decision
    draws: npt.NDArray[np.int64] | None
    elapsed_s: float
    fit_order: list[str] = field(default_factory=list)  # every fit, in order, with the events it used
    not_applicable: dict[str, str] = field(default_factory=dict)  # candidate -> why the vehicle has no such effect
    identification: Identification | None = None  # the base parameters identified first (None: not needed/possible)
    identified_score: CandidateScore | None = None  # the identified base on held-out events, against the file's
    nominal_gap: Interval | None = None  # held-out residual-to-noise ratio of the file's vehicle
    identification_note: str = ""  # what the identification meant for the diagnosis, or why there is none
    file_baseline: Evaluation | None = None  # the file's vehicle calibrated, when the identified one is the baseline

    def heldout(self) -> list[int]:
        return list(self.split.heldout)


def evaluate(base: Vehicle, fitted: FitResult, events: Sequence[DiagEvent], model: str,
             phases: dict[int, PhaseTimes] | None, period: float) -> Evaluation:
    """Predictions and scores of a fitted model on ``events`` (no parameter changes)."""
    veh = vehicle_with(base, fitted.nuisance, fitted.settings)
    scores: dict[int, EventScore] = {}
    preds: dict[int, Prediction] = {}
    outs = simulate_events(events, veh, fitted.nuisance.gain, fitted.settings, model)
    for ev, out in zip(events, outs, strict=True):
        pred = prediction(ev, out, fitted.nuisance.offset_s)
        r = weighted_residual(ev, pred)
        ph = phases[ev.index] if phases and ev.index in phases else phase_times(ev, pred)
        chi, cnt = phase_chi2(r, ph.labels(ev.speed_t))
        raw = ev.speed_meas - pred.speed
        _, ru = uniform(ev, raw, period)
        scores[ev.index] = EventScore(ev.index, float(r @ r), ev.n, float(raw @ raw), chi, cnt, band_energy(ru, period))
        preds[ev.index] = pred
    return Evaluation(fitted, scores, preds)


def _refit_first(vehicle: Vehicle, cal: Sequence[DiagEvent], split: Split, first: str,
                 evals: dict[str, Evaluation], pair_ids: Sequence[str], bounds: Bounds,
                 opts: DiagnosisOptions) -> FitResult | None:
    """The first effect fitted alone again, from the values the best pair (on calibration events) gave it.

    A pair fit starts from the single fit and has more freedom, so it can leave a local minimum the
    single fit stopped in; the second effect then takes the credit for what is a better fit of the
    first. Refitted from the pair's values, the single keeps whichever of its two fits is better on
    the calibration events (None: the first fit). Held-out data play no part in the choice.
    """
    single = evals[first].fit
    best = min((evals[p].fit for p in pair_ids), key=lambda f: f.chi2, default=None)
    if best is None or best.chi2 >= single.chi2:
        return None
    start = FitResult((first,), best.nuisance, {first: best.values[first]}, 0.0, 0, 0)
    again = fit(vehicle, cal, split, (get_effect(first),), bounds=bounds, model=opts.model, start=start,
                screen=False, seed=opts.seed)
    return again if again.chi2 < single.chi2 else None


def run_diagnosis(
    events: Sequence[DiagEvent],
    noise: NoiseFloor,
    vehicle: Vehicle,
    options: DiagnosisOptions | None = None,
    progress: Progress | None = None,
    skipped: Sequence[dict[str, object]] = (),
) -> DiagnosisResult:
    """Diagnose the sim-to-real gap of one log, in stages whose cost does not grow with the drive.

    The sequential design: the frozen split is made on every event; each side is taken in a stratified order
    (:func:`.split.stratified_order`: every prefix covers tip-ins and tip-outs in proportion and spans their
    speeds and torque steps), and stage *k* diagnoses the first 24 x 2^k events of each side
    (:func:`stage_sizes`). The design stops after the first stage whose decision (status and effects) equals the
    previous stage's, or when a stage holds every event. A log of up to about 32 events per side (a 60 s drive)
    is one stage of all its events, as before. The events a stopped design did not need are reported under
    ``events_skipped`` with the reason.

    Parameters
    ----------
    events : prepared event data (:func:`.prepare.prepare`).
    noise : model-free noise floor of the speed channel.
    vehicle : the diagnosed vehicle (its effects as the file says).
    options : candidate subset, split seed, model, decision rules.
    progress : ``progress(fraction in [0, 1], message)`` (the time left is the caller's: ``app.progress.eta_seconds``).
    skipped : events left out upstream, reported as such.
    """
    opts = options or DiagnosisOptions()
    t0 = time.perf_counter()
    say = progress or (lambda f, m: None)
    split = make_split(events, opts.seed)
    cal = stratified_order(split.calibration_events(events))
    ho = stratified_order(split.heldout_events(events))
    sizes = stage_sizes(max(len(cal), len(ho)), opts.stage_events)
    if len(sizes) == 1 or not opts.sequential:
        return _diagnose(events, noise, vehicle, opts, say, skipped, split)
    planned = float(sizes[0] + sizes[1])  # the stages' cost grows with their events; at least two stages run
    done = 0.0
    history: list[tuple[int, str]] = []
    res: DiagnosisResult | None = None
    with stage_starts() as memory:
        for k, n in enumerate(sizes):
            keep = {e.index for e in (*cal[:n], *ho[:n])}
            sub = [e for e in events if e.index in keep]

            def staged(frac: float, msg: str, k: int = k, n: int = n, done: float = done,
                       planned: float = planned) -> None:
                say(min((done + frac * n) / planned, 0.99), f"stage {k + 1} ({n} events per side): {msg}")

            memory.next_stage()
            res = _diagnose(sub, noise, vehicle, opts, staged, skipped, restricted(split, sub))
            d = res.decision
            history.append((n, f"{d.status} {'+'.join(d.top)}".rstrip()))
            done += n
            if k == len(sizes) - 1 or (k >= 1 and history[-1][1] == history[-2][1]):
                break
            planned = max(planned, done + sizes[k + 1])
    assert res is not None
    used = {e.index for e in res.events}
    stable = len(history) < len(sizes) or history[-1][1] == history[-2][1]
    why = (f"not needed: the sequential design stopped at {history[-1][0]} events per side, where the decision "
           f"({history[-1][1]}) equals the previous stage's" if stable else "")
    res.skipped.extend({"index": e.index, "reason": why} for e in events if e.index not in used)
    res.fit_order.insert(0, "sequential design (events per side: decision): "
                         + "; ".join(f"{n}: {dec}" for n, dec in history)
                         + (" -- stable, stopped" if stable and len(history) < len(sizes) else " -- all events"))
    res.elapsed_s = time.perf_counter() - t0
    progress and progress(1.0, f"decision: {res.decision.status} {' + '.join(res.decision.top)}".rstrip())
    return res


@single_blas_thread()  # the fit's thousands of small BLAS calls would wake spinning workers (see the module)
def _diagnose(
    events: Sequence[DiagEvent],
    noise: NoiseFloor,
    vehicle: Vehicle,
    opts: DiagnosisOptions,
    say: Progress,
    skipped: Sequence[dict[str, object]],
    split: Split,
) -> DiagnosisResult:
    """One stage of :func:`run_diagnosis`: the diagnosis of ``events`` on ``split``."""
    t_start = time.perf_counter()
    cal = split.calibration_events(events)
    ho = split.heldout_events(events)
    ho_idx = [e.index for e in ho]
    rules = opts.rules
    period = noise.period_s

    def result(decision: Decision, **kw: object) -> DiagnosisResult:
        base_kw: dict[str, object] = {"baseline": None, "candidates": {}, "singles": [], "pairs": [], "phases": {},
                                      "draws": None, "fit_order": []}
        base_kw.update(kw)
        return DiagnosisResult(opts, vehicle.name, split, noise, list(events), list(skipped), decision=decision,
                               elapsed_s=time.perf_counter() - t_start, **base_kw)  # type: ignore[arg-type]

    if min(len(cal), len(ho)) < rules.min_events_per_side:
        reason = (f"{len(events)} usable events ({len(cal)} calibration, {len(ho)} held-out); at least "
                  f"{2 * rules.min_events_per_side} are needed, {rules.min_events_per_side} on each side")
        if skipped:
            reason += f"; {len(skipped)} events were left out (see events_skipped)"
        return result(Decision("insufficient_data", reason=reason))

    # an effect the vehicle cannot have (housing_mount without a housing) is not a candidate: it would fit as a no-op
    not_applicable = {c: why for c in opts.candidates if (why := get_effect(c).inapplicable(vehicle))}
    candidates = [c for c in opts.candidates if c not in not_applicable]
    n_steps = 2 + len(candidates) + min(opts.max_pairs, max(len(candidates) - 1, 0))
    step = [0]

    def tick(msg: str) -> None:
        step[0] += 1
        say(min(step[0] / n_steps, 0.99), msg)

    bounds = Bounds.for_period(period)
    fit_order: list[str] = []
    say(0.0, f"baseline calibration on {len(cal)} events (held out: {len(ho)})")
    base_fit = fit(vehicle, cal, split, (), bounds=bounds, model=opts.model, seed=opts.seed)
    # add what the torque channel cannot tell (reconstruction, its noise, its quantisation) to every sample's
    # variance, then recalibrate
    events = with_input_uncertainty(events, vehicle, base_fit, opts.model, noise, opts.model_form_rel, opts.seed)
    cal = split.calibration_events(events)
    ho = split.heldout_events(events)
    base_fit = fit(vehicle, cal, split, (), bounds=bounds, model=opts.model, start=base_fit, seed=opts.seed)
    fit_order.append(f"baseline: {[e.index for e in cal]}")
    base_eval = evaluate(vehicle, base_fit, events, opts.model, None, period)
    phases = {ev.index: phase_times(ev, base_eval.predictions[ev.index]) for ev in events}
    base_eval = evaluate(vehicle, base_fit, events, opts.model, phases, period)
    tick("baseline calibrated")
    traverse = float(np.median([ph.resolved_samples for ph in phases.values()])) if phases else 0.0
    if "backlash" in candidates and traverse < MIN_TRAVERSE_SAMPLES and any(
            ph.t_close > ph.t_open for ph in phases.values()):
        not_applicable["backlash"] = (f"the lash traverse spans {traverse:g} speed samples in the median event (under "
                                      f"{MIN_TRAVERSE_SAMPLES}): where the lash sits cannot be told from this log")
        candidates.remove("backlash")

    draws = bootstrap_draws(len(ho), rules, opts.seed + 1)
    b = base_eval.chi2(ho_idx)
    n = np.array([base_eval.scores[i].n for i in ho_idx], dtype=np.float64)
    if not has_gap(gap_ratio(b, n, draws, rules.level), rules):
        # the model fits: rule 2 decides on the baseline alone, whatever a candidate would do (a fit to a
        # residual at the noise floor wanders over a flat objective and spends its whole pass budget)
        fit_order.append("candidates: not fitted (the baseline residual is not clearly above the noise floor)")
        decision = with_tones(decide(b, n, [], [], draws, rules, len(cal)), noise.tones)
        say(1.0, f"decision: {decision.status}")
        return result(decision, baseline=base_eval, phases=phases, draws=draws, fit_order=fit_order,
                      not_applicable=not_applicable)
    nominal_gap = gap_ratio(b, n, draws, rules.level)
    nominal = vehicle
    ident, ident_score, rebased, ident_note, file_eval = None, None, None, "", None
    bound_stop: Decision | None = None  # "identify the vehicle first", unless an effect brings the base inside
    too_few = ""  # why the vehicle could not be identified for want of events
    refit_with: Identification | None = None  # base parameters the best effects are refitted with
    joint_ident: dict[str, Identification] = {}  # candidate -> the base parameters identified jointly with it
    say(step[0] / n_steps, "identifying the vehicle's base parameters on calibration events")
    try:
        ident = identify_events(events, noise, vehicle, FitOptions(model=opts.model, seed=opts.seed), split=split,
                                baseline=base_fit)
    except (InsufficientDataError, NotIdentifiableError) as exc:
        ident_note = f"not identified: {exc}"
        too_few = str(exc) if isinstance(exc, InsufficientDataError) else ""
    if ident is not None:
        fit_order.append(f"identification ({', '.join(ident.ratios) or 'nothing fitted'}): "
                         f"{[e.index for e in cal]}")
        # the identification's fits apply to the file's vehicle under the contact law the log chose (form)
        nominal = ident.on or vehicle
        id_eval = evaluate(nominal, ident.fit, ho, opts.model, phases, period)
        ident_score = score_candidate(BASE_ID, (), b, id_eval.chi2(ho_idx), n, draws, rules,
                                      remainder(ho, id_eval.scores, id_eval.predictions, period))
        outcome = judge(ident, ident_score, n, draws, rules, nominal_gap)
        ident_note = outcome.note
        if outcome.stop is not None and outcome.stop.details.get("identify_first"):
            # a base parameter on its prior bound: either the file is further off than the priors allow, or missing
            # physics pushed the base there (a tyre's compliance taken as a lighter car with more lash). The
            # candidates are fitted on the file's vehicle and the best refitted jointly with the base parameters;
            # an effect is named only if, fitted with it, every base parameter comes back inside its prior
            # (below); otherwise the answer stays "identify the vehicle first"
            bound_stop = outcome.stop
            refit_with = ident
            ident = replace(ident, params={k: replace(p, named=False) for k, p in ident.params.items()})
            fit_order.append("identification: a base parameter on its prior bound; candidates fitted on the file's "
                             "vehicle, an effect named only with every base parameter inside its prior")
        elif outcome.stop is not None:
            # the file's error explains the gap; which effects would change the log alike on a right data sheet
            say(step[0] / n_steps, "screening the candidates on the file's vehicle")
            screen = screen_partners(vehicle, cal, base_fit, candidates, opts.model, bounds)
            fit_order.append(f"candidates on the file's vehicle (linearised gain): "
                             f"{', '.join(s.describe() for s in screen)}")
            decision = with_tones(mimicked_by(outcome.stop, screen, base_fit), noise.tones)
            say(1.0, f"decision: {decision.status}")
            return result(decision, baseline=base_eval, candidates={BASE_ID: id_eval}, phases=phases, draws=draws,
                          fit_order=fit_order, not_applicable=not_applicable, identification=ident,
                          identified_score=ident_score,
                          nominal_gap=nominal_gap, identification_note=ident_note)
        elif outcome.use:  # the candidates explain only what the identified vehicle cannot
            rebased, file_eval, refit_with = ident, base_eval, ident
            vehicle = ident.vehicle
            base_fit = nuisance_only(ident)
            base_eval = evaluate(vehicle, base_fit, events, opts.model, None, period)
            phases = {ev.index: phase_times(ev, base_eval.predictions[ev.index]) for ev in events}
            base_eval = evaluate(vehicle, base_fit, events, opts.model, phases, period)
            b = base_eval.chi2(ho_idx)
        else:
            # the base alone does not help, but where it says the file is off the best effects are still refitted
            # with it (an effect can hide the base's signature from a base-only fit, e.g. a lag taking the gain)
            refit_with = ident if ident.named else None
            ident = replace(ident, params={k: replace(p, named=False) for k, p in ident.params.items()})
    evals: dict[str, Evaluation] = {}
    singles: list[CandidateScore] = []

    def held_out(cid: str, effects: tuple[str, ...], fitted: FitResult, on: Vehicle | None = None) -> CandidateScore:
        """Evaluate ``fitted`` (on ``on``, default the base vehicle) on the held-out events (kept in ``evals[cid]``)
        and score it."""
        evals[cid] = evaluate(on or vehicle, fitted, ho, opts.model, phases, period)
        rem = remainder(ho, evals[cid].scores, evals[cid].predictions, period)
        return score_candidate(cid, effects, b, evals[cid].chi2(ho_idx), n, draws, rules, rem)

    def pair_scored(first: str, second: str, fitted: FitResult) -> CandidateScore:
        """A pair fit (``second`` its last effect) scored on the held-out events, with the first effect's share: the
        pair's fit with ``second`` switched off."""
        alone = replace(fitted, effects=fitted.effects[:-1], settings=fitted.settings[:-1],
                        values={k: v for k, v in fitted.values.items() if k != second})
        first_only = evaluate(vehicle, alone, ho, opts.model, phases, period).chi2(ho_idx)
        # a trade-off between the two effects' parameters, as (first's parameter, second's, correlation)
        tangled = next(((x, y, r) if x.split(".")[0] == first else (y, x, r) for x, y, r in fitted.trade_offs
                        if {x.split(".")[0], y.split(".")[0]} == {first, second}), None)
        return replace(held_out(f"{first}+{second}", (first, second), fitted), without_second=first_only,
                       entangled=tangled)

    quiet = rebased is not None and not rebased.named and not has_gap(gap_ratio(b, n, draws, rules.level), rules)
    if quiet:  # the contact law the log chose leaves no clear gap: nothing for a candidate to explain
        fit_order.append("candidates: not fitted (with the contact law the log chose, the residual is not clearly "
                         "above the noise floor)")
    for cid in () if quiet else candidates:
        say(step[0] / n_steps, f"fitting {cid}")
        f = fit(vehicle, cal, split, (get_effect(cid),), bounds=bounds, model=opts.model, start=base_fit,
                seed=opts.seed)
        fit_order.append(f"{cid}: {[e.index for e in cal]}")
        singles.append(held_out(cid, (cid,), f))
        tick(f"{cid}: held-out shrink {100 * singles[-1].shrink.value:.0f} %")

    pairs: list[CandidateScore] = []
    ranked = sorted(singles, key=lambda c: float(c.chi2.sum()))
    # pairs follow the remainder: tried whenever the best single effect leaves structure, whatever its share
    if ranked and len(ranked) > 1 and (ranked[0].explained.value < rules.explained_share
                                       or structured(ranked[0], rules)):
        first = ranked[0].id
        # partners by what each could add to the best single fit, to first order, on calibration events: the
        # choice does not peek at held-out data, and an effect that fits to "off" alone is still found
        say(step[0] / n_steps, f"screening partners of {first}")
        screen = screen_partners(vehicle, cal, evals[first].fit, [c for c in candidates if c != first], opts.model,
                                 bounds)
        fit_order.append(f"partners of {first} (linearised gain): {', '.join(s.describe() for s in screen)}")
        one = evals[first].fit
        least = max(opts.min_partner_gain * max(one.chi2 - one.n, 0.0), float(np.sqrt(2.0 * one.n)))
        for s in screen[:opts.max_pairs]:
            if s.starts and s.gain < least:
                fit_order.append(f"{first}+{s.id}: not fitted (linearised gain {s.gain:.1f} under {least:.1f}: "
                                 f"{100 * opts.min_partner_gain:g} % of the remainder above noise or one standard "
                                 "deviation of the noise's chi2)")
                continue
            second = s.id
            say(step[0] / n_steps, f"fitting {first} + {second}")
            pid = f"{first}+{second}"
            at = [{first: one.values[first], second: st} for st in s.starts]
            start = FitResult((), one.nuisance, at[0] if at else {}, 0.0, 0, 0)
            f = fit(vehicle, cal, split, (get_effect(first), get_effect(second)), bounds=bounds, model=opts.model,
                    start=start, screen=not at, alternatives=at[1:], passes_per_param=PAIR_PASSES_PER_PARAM,
                    seed=opts.seed)
            fit_order.append(f"{pid}: {[e.index for e in cal]}")
            # a first-effect parameter the single fit left on a prior bound and the pair's fit moves inside it
            relieved = next(((k, one.values[first][k.split(".", 1)[1]], f.values[first][k.split(".", 1)[1]])
                             for k in one.at_bound if k.split(".")[0] == first and k not in f.at_bound), None)
            pairs.append(replace(pair_scored(first, second, f), relieves=relieved))
            tick(f"{pid}: held-out shrink {100 * pairs[-1].shrink.value:.0f} %")
        refined = _refit_first(vehicle, cal, split, first, evals, [p.id for p in pairs], bounds, opts)
        if refined is not None:
            fit_order.append(f"{first} (again, from the pair's values): {[e.index for e in cal]}")
            again = held_out(first, (first,), refined)
            singles = [again if s.id == first else s for s in singles]

    def refit_jointly(cid: str, base: Identification, scored: list[CandidateScore], why: str,
                      from_file: tuple[FitResult, tuple[dict[str, float], ...]] | None = None) -> list[CandidateScore]:
        """Effect ``cid`` refitted jointly with ``base``'s parameters from the file's vehicle (``joint_with_base``),
        kept where it fits the calibration events better than the effect's fit so far, like every fit: then scored
        on the held-out events in ``scored``'s place and its base parameters kept in ``joint_ident``."""
        joint = joint_with_base(nominal, base, cal, split, cid, evals[cid].fit, bounds, opts.model, from_file,
                                single_on_file=rebased is None)
        fit_order.append(f"{cid} + base parameters (jointly, {why}): {[e.index for e in cal]}")
        if joint is None or joint.chi2 >= evals[cid].fit.chi2:
            return scored
        again = held_out(cid, (cid,), joint, on=nominal)
        joint_ident[cid] = identified_with(nominal, [k for k in base.ratios if BASE_EFFECTS[k].id in joint.values],
                                           joint, cal, base.chi2_before, held=base)
        return [again if c.id == cid else c for c in scored]

    if refit_with is not None and singles:
        # the best effect refitted jointly with the base parameters, from the nominal file: the identification
        # alone may have taken part of the effect (a mass and a torque gain standing in for a torque lag), and
        # the effect is judged on what the jointly identified base cannot explain
        # (the two best, so that the runner-up the decision compares with gets the same freedom)
        tops = [c.id for c in sorted(singles, key=lambda c: float(c.chi2.sum()))[:JOINT_REFITS]]
        from_file: dict[str, tuple[FitResult, tuple[dict[str, float], ...]]] = {}
        if rebased is not None and file_eval is not None:
            # the identified base can take an effect it mimics only in part (a shaft hardening under load read as
            # a stiffer shaft), and on that base the effect then adds nothing: each candidate's linearised gain on
            # the file's vehicle picks the one more to refit jointly, also from the file's values
            scr = screen_partners(nominal, cal, file_eval.fit, candidates, opts.model, bounds)
            fit_order.append(f"candidates on the file's vehicle (linearised gain): "
                             f"{', '.join(s.describe() for s in scr)}")
            for s in scr[:FILE_SCREEN_REFITS]:
                if s.starts and s.gain > float(np.sqrt(2.0 * file_eval.fit.n)):
                    from_file[s.id] = (file_eval.fit, s.starts)
                    tops += [] if s.id in tops else [s.id]
        for top in tops:
            say(step[0] / n_steps, f"refitting {top} jointly with the base parameters")
            singles = refit_jointly(top, refit_with, singles, "from the file's vehicle", from_file.get(top))
    decision = decide(b, n, singles, pairs, draws, rules, len(cal))
    base_src = refit_with if refit_with is not None else ident  # the base parameters an effect is refitted with
    first = decision.top[0] if decision.top else ""
    if (base_src is not None and base_src.ratios and len(decision.top) == 2 and first in evals
            and first not in joint_ident and decision.status in ("explained", "partial")):
        # a second effect is named only beside the first refitted with the base parameters: where the file is off
        # by less than the identification names, the second effect otherwise takes up the file's error (a mount
        # beside a drag, on a car whose lash was 15 % over the file's)
        say(step[0] / n_steps, f"refitting {first} jointly with the base parameters before naming a second effect")
        singles = refit_jointly(first, base_src, singles, f"before naming {decision.top[1]} beside it")
        if first in joint_ident:
            decision = decide(b, n, singles, pairs, draws, rules, len(cal))
    if (base_src is not None and bound_stop is None and len(decision.top) == 1 and decision.top[0] in joint_ident
            and decision.best is not None and decision.status in ("explained", "partial")):
        # the effect against the base parameters alone, refitted from its joint fit with the effect off: the
        # identification alone may have stopped short of the file's error that the joint fit found
        top = decision.top[0]
        say(step[0] / n_steps, f"refitting the base parameters alone from {top}'s joint fit")
        alone_fit = base_alone(nominal, base_src, evals[top].fit, cal, split, bounds, opts.model)
        refit = alone_fit.chi2 < base_src.fit.chi2  # else the identification is the better base alone
        alone_eval = evaluate(nominal, alone_fit, ho, opts.model, phases, period) if refit else id_eval
        alone_score = score_candidate(BASE_ID, (), b, alone_eval.chi2(ho_idx), n, draws, rules,
                                      remainder(ho, alone_eval.scores, alone_eval.predictions, period))
        preferred, p_better, apart_by = separation(decision.best, alone_score, n, draws, rules)
        # ... and a significant candidate with the base alone as its baseline: it removes a share of what the base
        # alone leaves above the noise floor, as any candidate must of the baseline's (rule 3)
        on_base = score_candidate(top, (top,), alone_score.chi2, decision.best.chi2, n, draws, rules)
        needed = preferred and on_base.significant
        fit_order.append(f"base parameters alone, from {top}'s joint fit: {[e.index for e in cal]} "
                         f"({'kept' if refit else 'the identification fits the calibration events better'}; "
                         f"{alone_score.noise_ratio(n):.2f}x the noise floor left, {top} "
                         f"{decision.best.noise_ratio(n):.2f}x; {top} {'preferred' if preferred else 'not preferred'} "
                         f"to the base alone, p = {p_better:.2f}, and explains {100 * on_base.explained.value:.0f} % "
                         f"[{100 * on_base.explained.lo:.0f}, {100 * on_base.explained.hi:.0f}] of what it leaves "
                         f"above the noise floor: {'named' if needed else 'not named'})")
        if not needed:
            refit_ident = identified_with(nominal, list(base_src.ratios), alone_fit, cal, base_src.chi2_before,
                                          held=base_src) if refit else base_src
            decision = with_tones(effect_not_needed(decision, refit_ident, decision.best, alone_score, n, nominal_gap,
                                                    p_better, apart_by, on_base.explained, rules), noise.tones)
            evals[BASE_ID] = alone_eval
            say(1.0, f"decision: {decision.status}")
            return result(decision, baseline=base_eval, candidates=evals, singles=singles, pairs=pairs, phases=phases,
                          draws=draws, fit_order=fit_order, not_applicable=not_applicable, identification=refit_ident,
                          identified_score=alone_score, nominal_gap=nominal_gap, identification_note=ident_note,
                          file_baseline=file_eval)
    decision = with_identifiability(decision, {k: e.fit for k, e in evals.items()}, vehicle)
    decision = lags_apart(decision, traverse, MIN_TRAVERSE_SAMPLES, candidates)
    if (chosen_fit := evals.get("+".join(decision.top))) is not None:
        decision = timing_unresolved(decision, chosen_fit.fit.at_bound, chosen_fit.fit.nuisance.offset_s)
    if too_few and decision.status in ("explained", "partial", "ambiguous"):
        # the vehicle could not be identified first: what the effect explains may be the data sheet's error (a
        # speed-sensor filter on its bound standing in for a damping twice the file's), so nothing is attributed
        decision = Decision("insufficient_data", gap_ratio=decision.gap_ratio, best=decision.best, reason=(
            f"{' + '.join(decision.top)} would explain part of the gap, but the vehicle could not be identified "
            f"first ({too_few}): an unmodelled effect cannot be told from a data sheet that is off on so few events"),
            details={"would_attribute": list(decision.top), "identify_first": True})
    if bound_stop is not None:
        top = "+".join(decision.top)
        jointly = joint_ident.get(top)
        inside = jointly is not None and not any(p.at_bound for k, p in jointly.params.items() if k in BASE_NAMES)
        if decision.status in ("explained", "partial") and inside:
            fit_order.append(f"{top}: with it every base parameter is inside its prior; attributed")
        else:
            why = ("no effect was attributed" if decision.status not in ("explained", "partial") else
                   f"{top} did not bring every base parameter inside its prior")
            fit_order.append(f"identify the vehicle first: {why}")
            decision = with_tones(bound_stop, noise.tones)
            say(1.0, f"decision: {decision.status}")
            evals[BASE_ID] = id_eval
            return result(decision, baseline=base_eval, candidates=evals, singles=singles, pairs=pairs, phases=phases,
                          draws=draws, fit_order=fit_order, not_applicable=not_applicable, identification=ident,
                          identified_score=ident_score, nominal_gap=nominal_gap, identification_note=ident_note)
    if rebased is not None and rebased.named and ident_score is not None and decision.status == "none_of_candidates" \
            and not withdrawn_for_timing(decision):
        decision = base_only(decision, rebased, ident_score, nominal_gap)
        evals[BASE_ID] = evaluate(nominal, rebased.fit, ho, opts.model, phases, period)
    elif ident is not None:  # the base parameters as identified with the chosen effect, where refitted with them
        ident = joint_ident.get("+".join(decision.top), ident)
        chosen = evals.get("+".join(decision.top))
        mixed = base_trade(decision, chosen.fit if chosen is not None else None) if ident.named else []
        # a trade-off inside the joint fit says the file's error *could* take part of the effect; it cannot stand in
        # for it when the identified base alone leaves much of the held-out gap unexplained (BASE_SHARE_APART), or
        # needed a prior bound to explain what it does, and held-out events prefer the effect to it (rule 4's
        # test). Where the base explains most of the gap, an effect is not told apart from it, even one that
        # removes most of what the base leaves: a mount did that with a 1 kHz drive's model form, after a base that
        # explained 84 % of the gap
        apart = None
        if mixed and ident_score is not None and decision.best is not None \
                and (bound_stop is not None or ident_score.explained.value < BASE_SHARE_APART):
            preferred, p_better, gap = separation(decision.best, ident_score, n, draws, rules)
            apart = (p_better, gap) if preferred else None
        if mixed and apart is None:  # the effect cannot be told from the base: the base is the answer
            decision = not_separable(decision, ident, mixed, nominal_gap, ident_score)
        else:
            decision = with_base(decision, ident, nominal_gap if rebased is not None else None)
            if "+".join(decision.top) not in joint_ident and rebased is None:  # the base played no part in the answer
                decision = replace(decision, details={k: v for k, v in decision.details.items()
                                                      if k != "base_parameters"})
            if mixed and apart is not None:
                decision = told_apart(decision, mixed, *apart)
    if rebased is not None:
        decision = with_form(decision, rebased)
    decision = with_tones(decision, noise.tones)
    say(1.0, f"decision: {decision.status} {' + '.join(decision.top)}".rstrip())
    return result(decision, baseline=base_eval, candidates=evals, singles=singles, pairs=pairs, phases=phases,
                  draws=draws, fit_order=fit_order, not_applicable=not_applicable, identification=ident,
                  identified_score=ident_score, nominal_gap=nominal_gap, identification_note=ident_note,
                  file_baseline=file_eval)
