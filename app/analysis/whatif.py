"""The ripple of simulated runs per tip-in/tip-out event, for what-ifs on a torque trace.

A whole torque trace of a drive holds accelerations and regenerative decelerations: the largest
peak-to-valley of the raw motor speed over it is mostly a speed swing of the drive (a 2 s fall
while regenerating), not the driveline's shuffle. A what-if is therefore answered per event: the
events are the tip-ins and tip-outs of the torque trace (:func:`app.analysis.events.find_events`
with the torque alone: no pedal, brake or road speed to corroborate or exclude them), the windows
are the analysis' (``pre_s`` before the crossing to ``post_s`` after, cut at the next reversal), and
each run's ripple in each window is the metrics' fluctuation: the peak-to-adjacent-valley of the
speed *detrended from the rigid-body trend* of that run's own torque
(:func:`app.analysis.metrics.ripple_metrics`). Runs are compared event by event and by the median.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from app.analysis.events import SPEED, TORQUE, Event, EventParams, find_events
from app.analysis.metrics import MetricParams, ripple_metrics
from app.analysis.series import FloatArray
from app.errors import InsufficientDataError
from app.signals import Signal, SignalSet

NAN = float("nan")


@dataclass(frozen=True)
class Run:
    """One simulated run: output times (s), motor speed (rpm) and the torque acting on the rotor (N m)."""

    label: str
    t: FloatArray
    speed_rpm: FloatArray
    torque_nm: FloatArray


@dataclass(frozen=True)
class EventRipple:
    """One event's window and each run's detrended fluctuation in it (rpm, NaN: no impact peak and valley)."""

    index: int
    kind: str
    t_cross_s: float
    t_start_s: float
    t_end_s: float
    fluctuation_rpm: tuple[float, ...]  # one per run, in the runs' order


def torque_events(t: FloatArray, torque: FloatArray, speed: FloatArray, params: EventParams | None = None,
                  ) -> list[Event]:
    """The tip-ins and tip-outs of a torque trace (with a speed for the windows' checks); included ones only."""
    p = params or EventParams()
    sigs = SignalSet({TORQUE: Signal(TORQUE, t, torque, "Nm"), SPEED: Signal(SPEED, t, speed, "rpm")})
    return [e for e in find_events(sigs, p).events if e.included]


def fluctuation(run: Run, ev: Event, params: MetricParams | None = None) -> float:
    """The run's detrended peak-to-adjacent-valley fluctuation (rpm) in the event's window; NaN if none."""
    m = (run.t >= ev.t_start_s) & (run.t <= ev.t_end_s)
    try:
        metrics = ripple_metrics(run.t[m], run.speed_rpm[m], Signal(TORQUE, run.t, run.torque_nm, "Nm"),
                                 ev.t_cross_s, ev.direction, params)
    except InsufficientDataError:
        return NAN
    return float(metrics.fluctuation_rpm)


def event_ripples(runs: Sequence[Run], events: Sequence[Event], params: MetricParams | None = None,
                  ) -> list[EventRipple]:
    """Every run's fluctuation in every event window."""
    return [EventRipple(ev.index, ev.kind.value, ev.t_cross_s, ev.t_start_s, ev.t_end_s,
                        tuple(fluctuation(r, ev, params) for r in runs)) for ev in events]


def medians(rows: Sequence[EventRipple], runs: int) -> tuple[float, ...]:
    """Median fluctuation (rpm) of each run over the events where it is determinable (NaN: none is)."""
    out = []
    for k in range(runs):
        v = np.array([r.fluctuation_rpm[k] for r in rows], dtype=np.float64)
        v = v[np.isfinite(v)]
        out.append(float(np.median(v)) if v.size else NAN)
    return tuple(out)


def median_ratio(rows: Sequence[EventRipple], a: int, b: int) -> float:
    """Median over the events of run ``b``'s fluctuation / run ``a``'s (events where both are determinable)."""
    r = np.array([row.fluctuation_rpm[b] / row.fluctuation_rpm[a] for row in rows
                  if np.isfinite(row.fluctuation_rpm[a]) and np.isfinite(row.fluctuation_rpm[b])
                  and row.fluctuation_rpm[a] > 0], dtype=np.float64)
    return float(np.median(r)) if r.size else NAN
