"""The diagnosis report as JSON (schema ``lashscope.diagnosis/1``).

Top-level keys (all numbers SI unless the key names a unit; intervals are
``{"value", "lo", "hi"}`` 90 % event-bootstrap intervals)::

    schema            "lashscope.diagnosis/1"
    vehicle, model    diagnosed vehicle name and simulator model
    options           {"candidates": [...], "seed": int, "rules": {...decision thresholds}}
    split             {"seed", "calibration": [event], "heldout": [event], "sha256", "strata"}
    noise_floor       {"sigma_rpm", "quant_step_rpm", "jitter_s", "period_s", "n_samples", "torque_step_nm",
                      "torque_sigma_nm", "tones": [{"order", "amplitude_rpm", "f_stat", "p_value", "blocks"}],
                      "retimed_bursts", "retimed_frames", "unresolved_bursts"}
    events_skipped    [{"index", "reason"}]
    decision          {"status": one of explained|partial|ambiguous|none_of_candidates|
                                 no_significant_gap|insufficient_data|base_parameters,
                       "top": [effect ids], "confusable": [id, id] | null, "reason": str,
                       "residual_to_noise_before": interval, "explained_share": interval,
                       "heldout_shrink": interval, "residual_to_noise_after": float,
                       "residual_rms_rpm_before", "residual_rms_rpm_after": held-out residual RMS (rpm) of the
                       baseline and of the chosen candidate, beside "noise_floor.sigma_rpm",
                       "dominant_event": {"index", "share", "residual_to_noise_without"} | null (a held-out
                                         event carrying most of the baseline's residual above noise, .decide),
                       "remainder_to_noise": {"overall": interval, "impact": interval, "phases": {phase: interval},
                                              "locked": {"value", "p_value", "null_95"}},
                       "remainder_above_noise": [names of the remainder statistics above noise],
                       "remainder": {"status": "noise" | "structured",
                                     "explained_by_candidates": bool | null (null: there was no gap),
                                     "where": ["overall" | "impact" | "locked" | "phase:<name>" |
                                               "motor order <k> (<a> rpm)"],
                                     "ratio_to_noise": float},
                       "tones": [as in noise_floor] (when the speed carries motor-order tones),
                       "identifiability": [{"params": [a, b], "correlation",
                                            "identified": {"name", "unit", "value", "nominal"} | null}]
                                          (only when the chosen fit has parameters that trade off),
                       "prefer_probability", "separation" (ambiguous only),
                       "base_parameters": [{"name", "label", "ratio", "lo", "hi", "value", "nominal", "unit"}]
                                          (the vehicle file's base parameters that the log says are off:
                                          ratio to the file's value with its 90 % interval; with
                                          ``base_parameters`` alone, or before an effect named on top),
                       "identify_first": bool (base_parameters: a parameter rests on its prior bound),
                       "mimicked_by": [{"effect", "linear_share"}] (base_parameters that explain the gap: the
                                          effects that would change the log alike on a right data sheet, to
                                          first order, with the share of the file's residual they remove)}
                      "explained_share" is the share of the residual *above the noise floor* removed,
                      "heldout_shrink" the relative drop of the residual energy; the reason quotes
                      both under these names (explained share, held-out shrink).
    baseline          fit: {"nuisance": {"offset_s", "gain", "road_load_grade_pct"}, "at_bound", ...}
    candidates        [{"id", "effects", "title", "fit": {"params": {effect: {name: value}},
                        "nuisance": {...}, "at_bound": [...], "trade_offs": [{"params", "correlation"}]},
                        "heldout": {"shrink", "explained_share",
                        "improved_fraction", "significant", "residual_to_noise", "residual_rms_rpm",
                        "remainder_to_noise"},
                        "phases": {phase: shrink interval}, "bands": {band: shrink interval}}]
    pairs             same shape, greedy pairs (first = best single effect)
    localisation      {"events": [{"index", "kind", "role", "t_event_s", "rms_rpm", "energy_share",
                         "residual_to_noise", "gap_traverse_samples", "features": {"measured": {...},
                         "baseline": {...}}}],
                       "phases": [{"phase", "energy_share", "residual_to_noise", "samples"}],
                       "bands": [{"band", "energy_share", "coherence"}],
                       "residual_torque_lag_s", "residual_torque_xcorr", "notes": [str]}
    identification    null (the file's vehicle had no significant gap), {"skipped": reason}, or
                       {"note", "params": {name: {"value", "lo", "hi", "nominal", "ratio", "ratio_lo",
                        "ratio_hi", "identified", "at_bound", "named", "unit", "label", "note"}}, "named",
                        "not_identified", "nuisance", "modal": {"freq_hz", "freq_ci", "zeta", ...} | null,
                        "heldout": {"shrink", "explained_share", "residual_to_noise"},
                        "residual_to_noise_nominal", ...} -- app.identify on the calibration events,
                        scored on the held-out ones against the file's vehicle
    fit_log           ["<fit>: [calibration event indices]"] -- every fit and the events it saw
    findings          [{"code", "channel", "message"}] -- problems of the log as decoded
                      (:mod:`app.analysis.logchecks`; empty when the log was not checked)
    elapsed_s

``localisation`` is computed on held-out events with the calibrated baseline.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.analysis.diagnosis.decide import CandidateScore, dominant_event
from app.analysis.diagnosis.localise import coherence_by_band, residual_torque_lag, uniform
from app.analysis.diagnosis.score import BAND_NAMES, PHASES, EventScore, shrink_interval
from app.analysis.diagnosis.select import DiagnosisResult, Evaluation
from app.analysis.logchecks import Finding
from app.analysis.metrics import ripple_metrics
from app.errors import AppError
from app.signals import Signal
from sim.effects import EFFECTS

SCHEMA_VERSION = "lashscope.diagnosis/1"
FEATURES = ("rise_height_rpm", "first_overshoot_rpm", "fluctuation_rpm", "shuffle_freq_hz", "damping_ratio")


def _f(x: float, nd: int = 4) -> float | None:
    return round(float(x), nd) if np.isfinite(x) else None


def rms_rpm(scores: list[EventScore]) -> float | None:
    """Residual RMS (rpm) over the samples of ``scores``: the residual in the speed's own unit."""
    n = sum(s.n for s in scores)
    return _f(float(np.sqrt(sum(s.sse_rpm2 for s in scores) / n)), 3) if n else None


def _phase_arrays(scores: list[EventScore], phase: str) -> np.ndarray:
    return np.array([s.phase_chi2[phase] for s in scores])


def _candidate(res: DiagnosisResult, sc: CandidateScore) -> dict[str, Any]:
    ev: Evaluation = res.candidates[sc.id]
    ho = res.heldout()
    base = [res.baseline.scores[i] for i in ho] if res.baseline else []
    cand = [ev.scores[i] for i in ho]
    phases = {}
    bands = {}
    if res.draws is not None and base:
        for p in PHASES:
            b, c = _phase_arrays(base, p), _phase_arrays(cand, p)
            phases[p] = shrink_interval(b, c, res.draws).to_dict() if b.sum() > 0 else None
        for name in BAND_NAMES:
            b = np.array([s.band_energy[name] for s in base])
            c = np.array([s.band_energy[name] for s in cand])
            bands[name] = shrink_interval(b, c, res.draws).to_dict() if b.sum() > 0 else None
    n = sum(s.n for s in cand)
    fit = ev.fit.to_dict()
    return {
        "id": sc.id,
        "effects": list(sc.effects),
        "title": " + ".join(EFFECTS[e].title for e in sc.effects),
        "fit": fit,
        "heldout": {
            "shrink": sc.shrink.to_dict(),
            "explained_share": sc.explained.to_dict(),
            "improved_fraction": round(sc.improved_fraction, 4),
            "significant": sc.significant,
            "residual_to_noise": _f(sum(s.chi2 for s in cand) / max(n, 1)),
            "residual_rms_rpm": rms_rpm(cand),
            "remainder_to_noise": sc.remainder.to_dict() if sc.remainder is not None else None,
        },
        "phases": phases,
        "bands": bands,
    }


def _features(t: np.ndarray, y: np.ndarray, torque: Signal, t_cross: float, direction: float) -> dict[str, Any]:
    try:
        m = ripple_metrics(t, y, torque, t_cross, direction)
    except (AppError, ValueError, np.linalg.LinAlgError):
        return {k: None for k in FEATURES}
    return {k: _f(getattr(m, k)) for k in FEATURES}


def _localisation(res: DiagnosisResult) -> dict[str, Any]:
    assert res.baseline is not None
    ho = set(res.heldout())
    period = res.noise.period_s
    total_sse = sum(res.baseline.scores[e.index].sse_rpm2 for e in res.events if e.index in ho) or 1.0
    rows = []
    resid_u, torque_u = [], []
    for ev in res.events:
        sc = res.baseline.scores[ev.index]
        pred = res.baseline.predictions[ev.index]
        torque = Signal("motor_torque_nm", ev.torque_t, ev.torque_nm, "N m")
        direction = 1.0 if ev.kind == "tip_in" else -1.0
        role = res.split.role(ev.index)
        rows.append({
            "index": ev.index, "kind": ev.kind, "role": role, "t_event_s": _f(ev.t_event),
            "rms_rpm": _f(np.sqrt(sc.sse_rpm2 / max(sc.n, 1)), 3),
            "energy_share": _f(sc.sse_rpm2 / total_sse) if role == "heldout" else None,
            "residual_to_noise": _f(sc.chi2 / max(sc.n, 1)),
            "gap_traverse_samples": res.phases[ev.index].resolved_samples,
            "features": {"measured": _features(ev.speed_t, ev.speed_meas, torque, ev.t_event, direction),
                         "baseline": _features(ev.speed_t, pred.speed, torque, ev.t_event, direction)},
        })
        if role == "heldout":
            _, r = uniform(ev, ev.speed_meas - pred.speed, period)
            _, q = uniform(ev, np.interp(ev.speed_t, ev.torque_t, ev.torque_nm), period)
            resid_u.append(r)
            torque_u.append(q)
    base = [res.baseline.scores[i] for i in res.heldout()]
    chi_tot = sum(s.chi2 for s in base) or 1.0
    phases = []
    for p in PHASES:
        c = sum(s.phase_chi2[p] for s in base)
        n = sum(s.phase_n[p] for s in base)
        phases.append({"phase": p, "energy_share": _f(c / chi_tot), "residual_to_noise": _f(c / n) if n else None,
                       "samples": n})
    e_tot = sum(sum(s.band_energy.values()) for s in base) or 1.0
    coh = coherence_by_band(resid_u, torque_u, period)
    bands = [{"band": b, "energy_share": _f(sum(s.band_energy[b] for s in base) / e_tot), "coherence": _f(coh[b])}
             for b in BAND_NAMES]
    lag, xc = residual_torque_lag(resid_u, torque_u, period)
    notes = []
    gap_samples = [res.phases[i].resolved_samples for i in res.heldout()]
    if gap_samples and float(np.median(gap_samples)) < 4:
        notes.append(f"the gap-traverse phase spans a median {float(np.median(gap_samples)):.0f} speed samples at "
                     f"{1 / period:.0f} Hz: its shape is not resolved; rely on the impact and oscillation phases")
    return {"events": rows, "phases": phases, "bands": bands, "residual_torque_lag_s": _f(lag),
            "residual_torque_xcorr": _f(xc), "notes": notes}


def _identification(res: DiagnosisResult) -> dict[str, Any] | None:
    if res.identification is None:
        return {"skipped": res.identification_note} if res.identification_note else None
    out = res.identification.to_dict()
    out["note"] = res.identification_note
    sc = res.identified_score
    if sc is not None:
        n = sum(res.baseline.scores[i].n for i in res.heldout()) if res.baseline else 0
        out["heldout"] = {"shrink": sc.shrink.to_dict(), "explained_share": sc.explained.to_dict(),
                          "residual_to_noise": _f(float(sc.chi2.sum()) / max(n, 1))}
    out["residual_to_noise_nominal"] = res.nominal_gap.to_dict() if res.nominal_gap is not None else None
    return out


def report_dict(res: DiagnosisResult, validation: dict[str, Any] | None = None,
                findings: list[Finding] | None = None) -> dict[str, Any]:
    """The JSON-ready report of a diagnosis (see the module docstring for the schema); ``findings``: the log
    checks' (:func:`app.analysis.diagnosis.validate.diagnose_checked`)."""
    decision = res.decision.to_dict()
    if res.decision.best is not None and res.baseline is not None:
        n = sum(res.baseline.scores[i].n for i in res.heldout())  # the same samples for every model
        decision["residual_to_noise_after"] = _f(float(res.decision.best.chi2.sum()) / max(n, 1))
        chosen = res.candidates.get(res.decision.best.id)
        decision["residual_rms_rpm_after"] = rms_rpm([chosen.scores[i] for i in res.heldout()]) if chosen else None
    if res.baseline is not None:
        base = [res.baseline.scores[i] for i in res.heldout()]
        # before: the file's vehicle, also when the candidates were fitted on the identified one
        decision["residual_rms_rpm_before"] = rms_rpm([(res.file_baseline or res.baseline).scores[i]
                                                       for i in res.heldout()])
        one = dominant_event(np.array([s.chi2 for s in base]), np.array([float(s.n) for s in base]),
                             res.options.rules)
        decision["dominant_event"] = None if one is None else {
            "index": base[one[0]].index, "share": _f(one[1]), "residual_to_noise_without": _f(one[2])}
    doc: dict[str, Any] = {
        "schema": SCHEMA_VERSION,
        "vehicle": res.vehicle_name,
        "model": res.options.model,
        "options": {"candidates": list(res.options.candidates), "seed": res.options.seed,
                    "rules": res.options.rules.to_dict()},
        "split": res.split.to_dict(),
        "noise_floor": {k: _f(v, 6) if isinstance(v, float) else v for k, v in res.noise.to_dict().items()},
        "events_skipped": list(res.skipped),
        "decision": decision,
        "baseline": res.baseline.fit.to_dict() if res.baseline else None,
        "candidates": [_candidate(res, s) for s in res.singles],
        "pairs": [_candidate(res, s) for s in res.pairs],
        "localisation": _localisation(res) if res.baseline else None,
        "identification": _identification(res),
        "fit_log": list(res.fit_order),
        "findings": [f.to_dict() for f in findings or []],
        "candidates_not_applicable": dict(res.not_applicable),
        "elapsed_s": round(res.elapsed_s, 3),
    }
    if validation is not None:
        doc["validation"] = validation
    return doc
