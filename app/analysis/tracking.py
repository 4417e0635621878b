"""Is the measured-versus-simulated comparison valid? A tracking verdict per event and per log.

Metric differences only mean something when the simulation follows the measured speed: a
model of a very different vehicle, a wheel spinning up or a wrong time offset all give
numbers that look like answers. The verdict is ``good`` when every check below passes,
``poor`` otherwise (with one reason per failed check, in words), ``unknown`` when nothing
could be compared. Metrics are returned either way; the verdict says whether to trust them.

Per event (thresholds in :class:`TrackingParams`):

- ``nrmse`` of the aligned speeds above ``max_nrmse``;
- shuffle frequency, simulated vs measured, off by more than ``max_freq_mismatch`` (relative).

Per log:

- more than ``max_poor_share`` of the analysed events poor;
- the open-loop whole-log simulation drifting away: the largest ``drift_window_s`` moving mean
  of ``simulated - measured`` above ``max_whole_drift`` of the measured speed range (wheelspin,
  brakes or grade the model does not know);
- reasons found before the comparison (the vehicle file's ratio and tyre radius not fitting
  the log's motor and road speeds: :func:`app.analysis.slip.log_ratio_scale`);
- the torque-to-speed offset's correlation below ``min_offset_correlation`` (the offset is then
  not applied: the simulated ripple does not line up with the measured one at any lag).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from app.analysis.compare import EventComparison
from app.analysis.series import FloatArray, moving_mean
from app.serial import Serial

GOOD, POOR, UNKNOWN = "good", "poor", "unknown"


@dataclass(frozen=True)
class TrackingParams:
    max_nrmse: float = 0.2
    max_freq_mismatch: float = 0.25  # |f_sim - f_meas| / f_meas
    max_poor_share: float = 0.5
    max_whole_drift: float = 0.3  # of the measured speed range (max - min over the whole log)
    drift_window_s: float = 1.0
    min_offset_correlation: float = 0.5

    def __post_init__(self) -> None:
        for name in ("max_nrmse", "max_freq_mismatch", "max_whole_drift", "drift_window_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"TrackingParams.{name} = {getattr(self, name)!r}: must be > 0")
        for name in ("max_poor_share", "min_offset_correlation"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"TrackingParams.{name} = {getattr(self, name)!r}: must be in [0, 1]")


@dataclass(frozen=True)
class Verdict(Serial):
    verdict: str  # good, poor or unknown
    reasons: list[str] = field(default_factory=list)


def event_verdict(c: EventComparison, p: TrackingParams) -> Verdict:
    """Does the simulation follow the measured speed through this event?"""
    reasons: list[str] = []
    nrmse = c.error.nrmse
    if not np.isfinite(nrmse):
        return Verdict(UNKNOWN, ["no aligned samples to compare"])
    if nrmse > p.max_nrmse:
        reasons.append(f"NRMSE {nrmse:.2f} > {p.max_nrmse:g}: the simulated speed does not follow the measured one")
    fm, fs = c.measured.shuffle_freq_hz, c.simulated.shuffle_freq_hz
    if np.isfinite(fm) and np.isfinite(fs) and fm > 0 and abs(fs - fm) / fm > p.max_freq_mismatch:
        reasons.append(f"shuffle frequency {fs:.1f} Hz simulated vs {fm:.1f} Hz measured "
                       f"({100 * (fs - fm) / fm:+.0f} %, limit ±{100 * p.max_freq_mismatch:g} %)")
    return Verdict(POOR if reasons else GOOD, reasons)


def whole_drift(t: FloatArray, measured: FloatArray, simulated: FloatArray, window_s: float) -> tuple[float, float]:
    """Largest ``window_s`` moving mean of ``simulated - measured`` (rpm, signed) and its time (s)."""
    ok = np.isfinite(measured) & np.isfinite(simulated)
    if ok.sum() < 2:
        return float("nan"), float("nan")
    tt = t[ok]
    mean = moving_mean(tt, simulated[ok] - measured[ok], window_s)
    k = int(np.argmax(np.abs(mean)))
    return float(mean[k]), float(tt[k])


def log_verdict(events: list[Verdict], p: TrackingParams, offset_corr: float | None = None,
                whole: tuple[FloatArray, FloatArray, FloatArray] | None = None,
                found: list[str] | None = None) -> Verdict:
    """Verdict over the log from the event verdicts, the offset's correlation and the whole-log run.

    ``offset_corr`` None: no offset was estimated. ``whole``: ``(t, measured, simulated)`` of
    the open-loop whole-log run, or None. ``found``: reasons established elsewhere (e.g. the
    vehicle's ratio not fitting the log's speeds), listed first.
    """
    reasons: list[str] = list(found or [])
    judged = [v for v in events if v.verdict != UNKNOWN]
    poor = [v for v in judged if v.verdict == POOR]
    if judged and len(poor) / len(judged) > p.max_poor_share:
        nrmse = sum(1 for v in poor if any(r.startswith("NRMSE") for r in v.reasons))
        freq = sum(1 for v in poor if any(r.startswith("shuffle frequency") for r in v.reasons))
        reasons.append(f"{len(poor)} of {len(judged)} analysed events do not track (NRMSE above "
                       f"{p.max_nrmse:g} in {nrmse}, shuffle frequency off by more than "
                       f"{100 * p.max_freq_mismatch:g} % in {freq})")
    if offset_corr is not None and not offset_corr >= p.min_offset_correlation:
        reasons.append(f"torque-to-speed offset not applied: its correlation {offset_corr:.2f} is below "
                       f"{p.min_offset_correlation:g} (the simulated ripple does not line up with the measured one)")
    if whole is not None:
        t, meas, sim = whole
        drift, at = whole_drift(t, meas, sim, p.drift_window_s)
        span = float(np.nanmax(meas) - np.nanmin(meas)) if np.isfinite(meas).any() else float("nan")
        if np.isfinite(drift) and span > 0 and abs(drift) > p.max_whole_drift * span:
            reasons.append(f"whole-log simulation drifts {drift:+.0f} rpm from the measured speed around "
                           f"t={at:.1f} s ({100 * abs(drift) / span:.0f} % of its {span:.0f} rpm range, limit "
                           f"{100 * p.max_whole_drift:g} %): wheel slip, brakes or grade the model does not know")
    if not judged and not reasons:
        return Verdict(UNKNOWN, ["no analysed event to judge"])
    return Verdict(POOR if reasons else GOOD, reasons)
