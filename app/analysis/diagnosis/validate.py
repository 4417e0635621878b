"""Signals in, diagnosis out; and the diagnosed effect checked on another drive.

:func:`validate_on` takes the fitted effect (parameters frozen from the diagnosed log) and the
baseline, re-fits *only the nuisance parameters* of each on the other drive (its time offset,
torque gain and road load are its own), and reports the shrink of the augmented model against
the baseline on every event of that drive, with event-bootstrap intervals.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from app.analysis.blas_threads import single_blas_thread
from app.analysis.diagnosis.calibrate import Bounds, fit
from app.analysis.diagnosis.decide import bootstrap_draws
from app.analysis.diagnosis.forward import DiagEvent
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, WindowParams, prepare
from app.analysis.diagnosis.score import Interval, explained_interval, shrink_interval
from app.analysis.diagnosis.select import (
    DiagnosisOptions,
    DiagnosisResult,
    Progress,
    evaluate,
    run_diagnosis,
)
from app.analysis.diagnosis.split import Split
from app.analysis.diagnosis.uncertainty import with_input_uncertainty
from app.analysis.events import EventParams, detect_events
from app.analysis.logchecks import CheckParams, Limits, LogChecks, check_log
from app.errors import AnalysisError, InsufficientDataError
from app.identify.base import with_base
from app.serial import Serial, rule
from app.signals import SignalSet
from sim import Vehicle
from sim.effects import apply_effects


def diagnose_signals(signals: SignalSet, vehicle: Vehicle, options: DiagnosisOptions | None = None,
                     progress: Progress | None = None, event_params: EventParams | None = None,
                     window: WindowParams | None = None) -> DiagnosisResult:
    """Detect events in decoded ``signals``, prepare them and run the diagnosis."""
    events = detect_events(signals, event_params or DIAGNOSIS_EVENTS)
    prepared, noise, skipped = prepare(signals, events, window)
    return run_diagnosis(prepared, noise, vehicle, options, progress, skipped)


def diagnose_checked(signals: SignalSet, vehicle: Vehicle, options: DiagnosisOptions | None = None,
                     progress: Progress | None = None, event_params: EventParams | None = None,
                     checks: CheckParams | None = None) -> tuple[DiagnosisResult, LogChecks]:
    """:func:`diagnose_signals` on a decoded log after the checks of :mod:`app.analysis.logchecks` (the
    analysis' own: an inverted torque corrected, a log decoded with the wrong DBC refused), and the checks."""
    checked = check_log(signals, Limits.for_vehicle(vehicle), checks)
    return diagnose_signals(checked.signals, vehicle, options, progress, event_params), checked


def chosen_effects(result: DiagnosisResult) -> dict[str, dict[str, float]]:
    """Fitted values of the decision's top effect(s) (empty when nothing was attributed)."""
    d = result.decision
    if not d.top or d.status not in ("explained", "partial", "ambiguous"):
        return {}
    key = "+".join(d.top)
    ev = result.candidates.get(key)
    if ev is None:
        return {}
    return {k: dict(v) for k, v in ev.fit.values.items() if k in d.top}  # not the base parameters fitted with it


def augmented_vehicle(result: DiagnosisResult, base: Vehicle) -> Vehicle:
    """``base`` with the diagnosed effect(s) applied at their fitted values (nuisance values are not kept).

    Base parameters the diagnosis named (``decision.details["base_parameters"]``) are applied first, at their
    identified values: the effect was fitted on that vehicle. ``base_parameters`` alone gives the identified
    vehicle (a diagnosis that stopped at a prior bound has no trusted values, and nothing to apply).
    """
    chosen = chosen_effects(result)
    items = result.decision.details.get("base_parameters") or []
    if result.decision.details.get("identify_first"):
        raise AnalysisError("the diagnosis stopped at a prior bound of a base parameter: identify the vehicle "
                            "(lashscope identify) and diagnose again with the identified file")
    if items and result.identification is not None:
        base = with_base(base, identified_ratios(result))
    elif not chosen:
        raise AnalysisError(f"diagnosis decided {result.decision.status!r}: there is no effect to apply")
    return apply_effects(base, chosen) if chosen else base


@dataclass(frozen=True)
class Validation(Serial):
    effects: dict[str, dict[str, float]]
    n_events: int = field(metadata=rule(key="events"))
    shrink: Interval
    explained: Interval = field(metadata=rule(key="explained_share"))
    improved_fraction: float = field(metadata=rule(digits=4))
    baseline_ratio: float = field(metadata=rule(key="residual_to_noise_baseline", digits=4))
    augmented_ratio: float = field(metadata=rule(key="residual_to_noise_augmented", digits=4))
    baseline_nuisance: dict[str, float] = field(metadata=rule(key="nuisance_baseline"))
    augmented_nuisance: dict[str, float] = field(metadata=rule(key="nuisance_augmented"))


def _all_calibration(events: Sequence[DiagEvent]) -> Split:
    # the other drive plays no part in the diagnosis; fitting its own nuisance values on all of its
    # events is not fitting the effect there (the effect's parameters stay frozen)
    return Split(-1, tuple(e.index for e in events), (), "other-drive")


def validate_on(result: DiagnosisResult, signals: SignalSet, vehicle: Vehicle,
                effects: dict[str, dict[str, float]] | None = None, progress: Progress | None = None,
                event_params: EventParams | None = None) -> Validation:
    """Shrink of the diagnosed (or given) effect on another drive, nuisance re-fitted, effect frozen."""
    chosen = effects if effects is not None else chosen_effects(result)
    ratios = identified_ratios(result)
    if not chosen and not ratios:
        raise AnalysisError(f"diagnosis decided {result.decision.status!r}: there is no effect to validate")
    return validate_effects(chosen, signals, vehicle, result.options, progress, event_params, ratios)


def identified_ratios(result: DiagnosisResult) -> dict[str, float]:
    """The identified base parameters (ratios to the file's) the decision rests on; {} when it names none."""
    if not result.decision.details.get("base_parameters") or result.decision.details.get("identify_first") \
            or result.identification is None:
        return {}
    return dict(result.identification.ratios)


@single_blas_thread()
def validate_effects(effects: dict[str, dict[str, float]], signals: SignalSet, vehicle: Vehicle,
                     options: DiagnosisOptions | None = None, progress: Progress | None = None,
                     event_params: EventParams | None = None,
                     base_ratios: Mapping[str, float] | None = None) -> Validation:
    """Shrink of ``vehicle`` + ``effects`` (values frozen) against ``vehicle`` on the drive in ``signals``.

    Each model gets its own nuisance fit (offset, gain, road load) on all events of this drive;
    nothing about the effect is fitted here. ``base_ratios``: identified base parameters applied first
    (ratios to the file's values, :func:`app.identify.base.with_base`).
    """
    opts = options or DiagnosisOptions()
    say = progress or (lambda f, m: None)
    evs = detect_events(signals, event_params or DIAGNOSIS_EVENTS)
    events, noise, _ = prepare(signals, evs)
    if len(events) < opts.rules.min_events_per_side:
        raise InsufficientDataError(f"the validation drive has {len(events)} usable events; need at least "
                                    f"{opts.rules.min_events_per_side}")
    split = _all_calibration(events)
    bounds = Bounds.for_period(noise.period_s)
    model = opts.model
    say(0.1, "validation: baseline nuisance fit")
    base_fit = fit(vehicle, events, split, (), bounds=bounds, model=model)
    events = with_input_uncertainty(events, vehicle, base_fit, model, noise, opts.model_form_rel, opts.seed)
    base_fit = fit(vehicle, events, split, (), bounds=bounds, model=model, start=base_fit)
    say(0.5, "validation: augmented nuisance fit")
    aug = apply_effects(with_base(vehicle, base_ratios or {}), effects)
    aug_fit = fit(aug, events, split, (), bounds=bounds, model=model, start=base_fit)
    b_eval = evaluate(vehicle, base_fit, events, model, None, noise.period_s)
    a_eval = evaluate(aug, aug_fit, events, model, None, noise.period_s)
    idx = [e.index for e in events]
    b, a = b_eval.chi2(idx), a_eval.chi2(idx)
    n = np.array([e.n for e in events], dtype=np.float64)
    draws = bootstrap_draws(len(idx), opts.rules, 7)
    say(1.0, "validation done")
    return Validation(effects, len(idx), shrink_interval(b, a, draws), explained_interval(b, a, n, draws),
                      float(np.mean(a < b)), float(b.sum() / n.sum()), float(a.sum() / n.sum()),
                      base_fit.nuisance.to_dict(), aug_fit.nuisance.to_dict())
