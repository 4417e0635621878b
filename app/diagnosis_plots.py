"""Diagnosis plots (matplotlib, Agg backend, PNG files).

- :func:`event_overlay_png`: per held-out event, measured speed, the calibrated baseline simulation
  and the augmented simulation (baseline plus the diagnosed effect), with the predicted gap-open
  span shaded;
- :func:`residual_chart_png`: residual-to-noise ratio per phase and residual energy share per
  frequency band for the baseline and the augmented model, from the held-out events.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

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
