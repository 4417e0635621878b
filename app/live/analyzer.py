"""Tip-in/tip-out events and their ripple metrics, reported live as each event completes.

The live analyzer runs the offline analysis (:func:`app.analysis.events.detect_events`
and the measured ripple metrics) on a rolling buffer of the canonical channels, and
reports an event only once nothing that can still arrive could change it. Then the live
events equal the offline analysis of the recorded log.

When is an event final? Its window end depends on the *next* accepted torque reversal
(``t_end = min(t_cross + post_s, next - min(pre_s, (next - t_cross) / 2))``), so every
reversal with a crossing before ``t_cross + post_s + pre_s`` must be known and decided:

* known: a reversal is confirmed only when the torque leaves the hysteresis band on the new
  side, and its crossing lies after the last torque sample outside the band; so all
  crossings before the time of the last out-of-band sample (``h_band``) are known;
* decided: acceptance reads the torque up to ``step_after_s[1]`` after the crossing.

So an event is final when ``h_band >= t_cross + post_s + pre_s`` and the data reach
``t_cross + post_s + pre_s + step_after_s[1] + rate_half_window_s``. At the end of a
session every remaining event is final (the recorded log ends there too).

Memory: the buffer keeps data from shortly before the earliest event that may still be
reported (or before ``h_band`` when none is pending), and never more than ``max_buffer_s``
seconds; an event whose data were cut by that cap is reported with ``"provisional": True``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from app.analysis.events import SPEED, TORQUE, Event, EventParams, detect_events
from app.analysis.metrics import MetricParams, ripple_metrics
from app.analysis.series import finite_signal
from app.errors import AppError
from app.signals import Interp, Signal, SignalSet

MARGIN_S = 2.0  # data kept before the earliest sample a pending event reads


class ChannelBuffer:
    """Growable (t, value) arrays for one channel, trimmed from the front."""

    def __init__(self, capacity: int = 4096) -> None:
        self.t = np.empty(capacity, np.float64)
        self.v = np.empty(capacity, np.float64)
        self.n = 0

    def append(self, t: np.ndarray, v: np.ndarray) -> None:
        k = t.size
        if self.n + k > self.t.size:
            cap = max(2 * self.t.size, self.n + k)
            self.t = np.concatenate([self.t[: self.n], np.empty(cap - self.n)])
            self.v = np.concatenate([self.v[: self.n], np.empty(cap - self.n)])
        self.t[self.n:self.n + k] = t
        self.v[self.n:self.n + k] = v
        self.n += k

    def trim_before(self, t_min: float) -> None:
        i = int(np.searchsorted(self.t[: self.n], t_min))
        if i:
            self.t[: self.n - i] = self.t[i:self.n]
            self.v[: self.n - i] = self.v[i:self.n]
            self.n -= i

    @property
    def last_t(self) -> float:
        return float(self.t[self.n - 1]) if self.n else float("-inf")

    @property
    def first_t(self) -> float:
        return float(self.t[0]) if self.n else float("inf")


def measured_metrics(signals: SignalSet, event: Event, params: MetricParams | None = None) -> dict[str, Any] | None:
    """Ripple metrics of the measured motor speed over the event window (None if excluded).

    The offline analysis also estimates a torque-to-speed offset pooled over all events of the
    log (from the simulation) and evaluates the metrics at that offset; a live session cannot know
    it before the drive ends, so live metrics use zero offset. They equal the offline metrics
    computed with ``AnalysisOptions(fit_offset=False)``; the analysis stored when the session stops
    has the offset-corrected values.
    """
    if not event.included:
        return None
    # as app.pipeline.analyze_signals does it, at zero torque-to-speed offset
    w = finite_signal(signals[SPEED]).window(event.t_start_s, event.t_end_s)
    try:
        m = ripple_metrics(w.t, w.values, finite_signal(signals[TORQUE]), event.t_cross_s, event.direction,
                           params or MetricParams())
    except AppError as exc:
        return {"error": str(exc), "code": exc.code}
    return m.to_dict()


class LiveAnalyzer:
    """Feed channel samples with :meth:`add`; collect final events with :meth:`completed`.

    Parameters
    ----------
    units : mapping name -> (unit, Interp)
        How to build each channel's :class:`Signal` (as the offline loader does).
    params, metric_params
        The same thresholds the offline analysis uses.
    max_buffer_s : float
        Hard cap on the buffered history (memory bound).
    """

    def __init__(self, units: Mapping[str, tuple[str, Interp]] | None = None, params: EventParams | None = None,
                 metric_params: MetricParams | None = None, max_buffer_s: float = 900.0) -> None:
        self.units = dict(units or {})
        self.params = params or EventParams()
        self.metric_params = metric_params
        self.max_buffer_s = max_buffer_s
        self._buf: dict[str, ChannelBuffer] = {}
        self._count = 0
        self._last_cross = float("-inf")
        self._capped_at = float("-inf")  # data before this time were dropped by the cap
        self.errors = 0
        self.last_error: str | None = None

    def add(self, channels: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None:
        for name, (t, v) in channels.items():
            if t.size:
                self._buf.setdefault(name, ChannelBuffer()).append(t, v)

    def signals(self) -> SignalSet:
        out = SignalSet()
        for name, b in self._buf.items():
            unit, interp = self.units.get(name, ("", Interp.LINEAR))
            out.add(Signal.from_samples(name, b.t[: b.n].copy(), b.v[: b.n].copy(), unit, interp))
        return out

    def _band_horizon(self) -> float:
        b = self._buf[TORQUE]
        tq = b.v[: b.n]
        out = np.flatnonzero(np.isfinite(tq) & (np.abs(tq) > self.params.hysteresis_nm))
        return float(b.t[out[-1]]) if out.size else float("-inf")

    def completed(self, final: bool = False) -> list[dict[str, Any]]:
        """Events that became final since the last call, as dicts with ``metrics``."""
        if TORQUE not in self._buf or SPEED not in self._buf:
            return []
        p = self.params
        h_data = min(b.last_t for b in self._buf.values())
        h_band = self._band_horizon()
        sig = self.signals()
        try:
            events = detect_events(sig, p)
        except AppError as exc:  # too little data yet
            self.last_error = str(exc)
            return []
        reach = p.post_s + p.pre_s
        done: list[dict[str, Any]] = []
        pending_from = h_band
        for ev in events:
            if ev.t_cross_s <= self._last_cross:
                continue
            if not final and not (h_band >= ev.t_cross_s + reach
                                  and h_data >= ev.t_cross_s + reach + p.step_after_s[1] + p.rate_half_window_s):
                pending_from = min(pending_from, ev.t_cross_s)
                break
            d = ev.to_dict()
            d["index"] = self._count
            d["metrics"] = measured_metrics(sig, ev, self.metric_params)
            d["provisional"] = ev.t_start_s - MARGIN_S < self._capped_at
            self._count += 1
            self._last_cross = ev.t_cross_s
            done.append(d)
        if not final:
            self._trim(pending_from, h_data)
        return done

    def _trim(self, pending_from: float, h_data: float) -> None:
        p = self.params
        keep_from = pending_from - max(p.pre_s, p.step_before_s[0]) - MARGIN_S
        cap_from = h_data - self.max_buffer_s
        if cap_from > keep_from:
            self._capped_at = max(self._capped_at, cap_from)
            keep_from = cap_from
        if np.isfinite(keep_from):
            for b in self._buf.values():
                b.trim_before(keep_from)
