"""Overlay plot of measured vs simulated motor speed per analysed event (PNG, matplotlib Agg)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.figure import Figure

from app.storage.results import ResultFiles


def overlay_png(files: ResultFiles, path: Path, max_events: int = 12, title: str = "") -> Path:
    """One panel per analysed event (up to ``max_events``): speed vs time from the torque crossing."""
    fig = overlay_figure(files, max_events, title)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def overlay_figure(files: ResultFiles, max_events: int = 12, title: str = "") -> Figure:
    """The figure of :func:`overlay_png` (Agg backend); the caller closes it."""
    doc: dict[str, Any] = files.doc
    metrics = {m["event_index"]: m for m in doc["metrics"]}
    events = [e for e in doc["events"] if e["has_series"] and e["index"] in metrics][:max_events]
    n = max(1, len(events))
    cols = min(4, n)
    rows = math.ceil(n / cols)
    # constrained layout reserves room for the figure-level labels; tight_layout ignores supylabel, which
    # then overlapped the tick labels of the first column
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.0 * rows), squeeze=False, layout="constrained")
    t_all, meas_all, sim_all = files.array("ev_t"), files.array("ev_measured_rpm"), files.array("ev_simulated_rpm")
    for ax, ev in zip(axes.flat, events, strict=False):
        a, b = doc["event_rows"][str(ev["index"])]
        t = np.asarray(t_all[a:b]) - ev["t_cross_s"]
        m = metrics[ev["index"]]
        ax.plot(t, meas_all[a:b], color="tab:blue", lw=1.2, label="measured")
        ax.plot(t, sim_all[a:b], color="tab:orange", lw=1.0, ls="--", label="simulated")
        fm, fs = m["measured"]["fluctuation_rpm"], m["simulated"]["fluctuation_rpm"]
        label = f"#{ev['index']} {ev['kind'].replace('_', '-')}"
        if fm is not None and fs is not None:
            label += f": {fm:.0f} vs {fs:.0f} rpm"
        ax.set_title(label, fontsize=9)
        ax.set_xlim(-0.3, min(1.2, float(t[-1])))
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(events):]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7, loc="best")
    fig.supxlabel("time from torque zero crossing (s)", fontsize=9)
    fig.supylabel("motor speed (rpm)", fontsize=9)
    fig.suptitle(title or "measured vs simulated motor speed (fluctuation peak-valley measured vs simulated)",
                 fontsize=10)
    return fig
