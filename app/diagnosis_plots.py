"""Diagnosis plots (matplotlib, Agg backend, PNG files) and the numbers behind them (JSON).

- :func:`event_overlay_png`: per held-out event, measured speed, the calibrated baseline simulation
  and the augmented simulation (baseline plus the diagnosed effect), with the predicted gap-open
  span shaded;
- :func:`residual_chart_png`: residual-to-noise ratio per phase and residual energy share per
  frequency band for the baseline and the augmented model, from the held-out events;
- :func:`chart_data`: the same numbers as JSON (schema ``lashscope.diagnosis-charts/1``) for the
  dashboard's own charts: residual-to-noise per held-out event and per phase before and after the
  chosen fit, band shares, and the measured / baseline / fitted speed of the held-out events on
  time from the torque zero crossing.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from app.analysis.diagnosis.rebase import BASE_ID
from app.analysis.diagnosis.score import BAND_NAMES, PHASES
from app.analysis.diagnosis.select import DiagnosisResult, Evaluation
from app.errors import AnalysisError


def _augmented(res: DiagnosisResult) -> tuple[str, Evaluation | None]:
    key = "+".join(res.decision.top)
    if key and key in res.candidates:
        return key, res.candidates[key]
    if res.singles:
        best = min(res.singles, key=lambda s: float(s.chi2.sum()))
        return f"{best.id} (best, not attributed)", res.candidates[best.id]
    return "", None


CHARTS_SCHEMA = "lashscope.diagnosis-charts/1"


def _num(x: float, digits: int) -> float | None:
    return round(float(x), digits) if np.isfinite(x) else None


def _nums(a: np.ndarray, digits: int) -> list[float | None]:
    return [_num(v, digits) for v in np.asarray(a, dtype=np.float64)]


def _ratio(chi2: float, n: float) -> float | None:
    return _num(chi2 / n, 4) if n else None


def chart_data(res: DiagnosisResult, max_events: int = 12) -> dict[str, object]:
    """The diagnosis charts' numbers: held-out residual by event, phase and band for the file's vehicle
    calibrated (``before``) and the chosen fit (``after``; the best single effect when none was chosen,
    the identified base parameters when they alone are the answer; named in ``fitted``), and the speed
    of up to ``max_events`` held-out events (rpm) on time from their torque zero crossing (s), with the
    predicted gap-open span. Ratios are residual / noise energy (1 = noise)."""
    if res.baseline is None:
        raise AnalysisError(f"no charts: the diagnosis decided {res.decision.status!r} ({res.decision.reason})")
    label, aug = _augmented(res)
    ho = res.heldout()
    base = res.baseline
    if res.file_baseline is not None:  # before: the file's vehicle; after: the identified one (with the effect)
        base = res.file_baseline
    if BASE_ID in res.candidates and (aug is None or res.decision.status == BASE_ID):  # they alone are the answer
        label, aug = "identified base parameters", res.candidates[BASE_ID]
    by_index = {e.index: e for e in res.events}
    events = []
    for i in ho:
        b = base.scores[i]
        a = aug.scores[i] if aug is not None and i in aug.scores else None
        events.append({"index": i, "kind": by_index[i].kind, "t_event_s": _num(by_index[i].t_event, 3),
                       "before": _ratio(b.chi2, b.n), "after": _ratio(a.chi2, a.n) if a else None})
    phases = []
    for p in PHASES:
        n = sum(base.scores[i].phase_n[p] for i in ho)
        before = sum(base.scores[i].phase_chi2[p] for i in ho)
        after = sum(aug.scores[i].phase_chi2[p] for i in ho) if aug is not None else None
        phases.append({"phase": p, "samples": int(n), "before": _ratio(before, n),
                       "after": _ratio(after, n) if after is not None else None})
    base_total = sum(sum(base.scores[i].band_energy.values()) for i in ho) or 1.0
    bands = [{"band": bn, "before": _num(sum(base.scores[i].band_energy[bn] for i in ho) / base_total, 4),
              "after": _num(sum(aug.scores[i].band_energy[bn] for i in ho) / base_total, 4) if aug is not None
              else None} for bn in BAND_NAMES]
    overlays = []
    for i in ho[:max_events]:
        ev = by_index[i]
        t0 = ev.t_event
        ph = res.phases.get(i)
        fitted = aug.predictions[i].speed if aug is not None and i in aug.predictions else None
        overlays.append({
            "index": i, "kind": ev.kind, "t_event_s": _num(t0, 3),
            "t_s": _nums(ev.speed_t - t0, 4), "measured_rpm": _nums(ev.speed_meas, 2),
            "baseline_rpm": _nums(base.predictions[i].speed, 2),
            "fitted_rpm": _nums(fitted, 2) if fitted is not None else None,
            "gap_open_s": _num(ph.t_open - t0, 4) if ph is not None and ph.t_close > ph.t_open else None,
            "gap_close_s": _num(ph.t_close - t0, 4) if ph is not None and ph.t_close > ph.t_open else None})
    return {"schema": CHARTS_SCHEMA, "status": res.decision.status, "top": list(res.decision.top),
            "fitted": label or None, "noise_sigma_rpm": _num(res.noise.sigma_rpm, 4), "heldout": len(ho),
            "events": events, "phases": phases, "bands": bands, "overlays": overlays}


def event_overlay_png(res: DiagnosisResult, path: Path, max_events: int = 6) -> Path:
    """Measured, baseline and augmented speed of up to ``max_events`` held-out events."""
    if res.baseline is None:
        raise AnalysisError(f"no plots: the diagnosis decided {res.decision.status!r} ({res.decision.reason})")
    label, aug = _augmented(res)
    ho = res.heldout()[:max_events]
    by_index = {e.index: e for e in res.events}
    fig, axes = plt.subplots(len(ho), 1, figsize=(9, 2.3 * len(ho) + 0.6), squeeze=False)
    for ax, i in zip(axes[:, 0], ho, strict=True):
        ev = by_index[i]
        base = res.baseline.predictions[i]
        t0 = ev.t_event
        ax.plot(ev.speed_t - t0, ev.speed_meas, ".", ms=3, color="black", label="measured")
        ax.plot(ev.speed_t - t0, base.speed, "-", lw=1.2, color="tab:blue", label="baseline")
        if aug is not None and i in aug.predictions:
            ax.plot(ev.speed_t - t0, aug.predictions[i].speed, "-", lw=1.2, color="tab:red", label=f"+ {label}")
        ph = res.phases.get(i)
        if ph is not None and ph.t_close > ph.t_open:
            ax.axvspan(ph.t_open - t0, ph.t_close - t0, color="0.85", zorder=0)
        ax.set_ylabel("rpm")
        ax.set_title(f"event {i} ({ev.kind}), held out", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8, loc="best")
    axes[-1, 0].set_xlabel("time from torque zero crossing (s)")
    fig.suptitle(f"{res.vehicle_name}: decision {res.decision.status} {' + '.join(res.decision.top)}", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def residual_chart_png(res: DiagnosisResult, path: Path) -> Path:
    """Per-phase residual-to-noise ratio and per-band energy share, baseline vs augmented (held-out)."""
    if res.baseline is None:
        raise AnalysisError(f"no plots: the diagnosis decided {res.decision.status!r} ({res.decision.reason})")
    label, aug = _augmented(res)
    ho = res.heldout()
    models = [("baseline", res.baseline)] + ([(f"+ {label}", aug)] if aug is not None else [])
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 3.6))
    width = 0.8 / len(models)
    x = np.arange(len(PHASES))
    for k, (name, ev) in enumerate(models):
        ratio = []
        for p in PHASES:
            c = sum(ev.scores[i].phase_chi2[p] for i in ho)
            n = sum(ev.scores[i].phase_n[p] for i in ho)
            ratio.append(c / n if n else 0.0)
        ax1.bar(x + k * width, ratio, width, label=name)
    ax1.axhline(1.0, color="black", lw=0.8, ls="--", label="noise floor")
    ax1.set_xticks(x + width * (len(models) - 1) / 2, [p.replace("_", "\n") for p in PHASES], fontsize=8)
    ax1.set_yscale("log")
    ax1.set_ylabel("residual / noise energy")
    ax1.set_title("by phase", fontsize=9)
    ax1.legend(fontsize=8)
    xb = np.arange(len(BAND_NAMES))
    base_total = sum(sum(res.baseline.scores[i].band_energy.values()) for i in ho) or 1.0
    for k, (name, ev) in enumerate(models):
        energy = [sum(ev.scores[i].band_energy[b] for i in ho) / base_total for b in BAND_NAMES]
        ax2.bar(xb + k * width, energy, width, label=name)
    ax2.set_xticks(xb + width * (len(models) - 1) / 2, list(BAND_NAMES), fontsize=8)
    ax2.set_ylabel("share of baseline residual energy")
    ax2.set_title("by frequency band", fontsize=9)
    fig.suptitle(f"held-out residual, {len(ho)} events", fontsize=10)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
