"""Torque reversals a driver makes, told apart from inverter ringing.

The torque is *driving* above ``+h`` (``hysteresis_nm``) and *not driving* otherwise: coasting
inside the band (a formula-student car coasts at exactly 0 N m) or regenerating below it. A
**tip-in** is not-driving -> driving, a **tip-out** driving -> not-driving; regeneration to
coast is no reversal of the driveline's load and no event.

A driver holds what they ask for; an inverter's ringing flips around the band in tens of ms.
A change of state counts only when

- the new state holds for ``min_dwell_s``: at least ``HOLD_SHARE`` of that time after the
  change (short excursions back are tolerated),
- the old state held for ``min_dwell_s`` before it: at least ``PRIOR_SHARE`` of that time
  (generous, so a real tip-in out of a ringing coast still counts), and
- the torque moves one way through the crossing: over ``t_cross ± rate_half_window_s`` (for
  a coast, over twice that on the ramp side only: the coast before a tip-in may still ring) at
  most ``max_ramp_reversal`` of the torque's travel goes against the event's direction, and
  the fitted rate (same span) has the event's sign.

Changes that fail are *rejected as ringing* and counted, not listed as events.

The crossing time ``t_cross`` is the last time the torque rises through 0 N m before a tip-in
enters the driving state (from a coast at exactly 0: the last sample at 0, where the ramp
starts), and the first time it falls through 0 N m after a tip-out leaves it; within
``CROSS_SEARCH_S``, else where it crosses ``+h``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.analysis.series import FloatArray

HOLD_SHARE = 0.8  # the new state must hold this share of min_dwell_s after the change
PRIOR_SHARE = 0.5  # the old state must have held this share of min_dwell_s before it
CROSS_SEARCH_S = 1.0  # the zero crossing is searched this far from the band exit


@dataclass(frozen=True)
class Reversal:
    tip_in: bool
    t_cross: float
    index: int  # first sample in the new state
    rate_nm_s: float  # least-squares slope at the crossing (signed)
    from_coast: bool  # the not-driving side is a coast (inside the band), not regeneration


@dataclass(frozen=True)
class ReversalParams:
    hysteresis_nm: float
    min_dwell_s: float
    max_ramp_reversal: float
    rate_half_window_s: float


def _share(t: FloatArray, driving: npt.NDArray[np.bool_], t0: float, t1: float, want: bool) -> float:
    grid = np.linspace(t0, t1, 41)
    idx = np.clip(np.searchsorted(t, grid, side="right") - 1, 0, t.size - 1)
    return float(np.mean(driving[idx] == want))


def _crossing(t: FloatArray, tq: FloatArray, r: int, tip_in: bool, h: float) -> float:
    """Zero crossing next to the state change at sample ``r`` (see the module docstring)."""
    pos = tq > 0.0
    if tip_in:
        lo = int(np.searchsorted(t, t[r] - CROSS_SEARCH_S))
        ch = np.flatnonzero(~pos[lo:r] & pos[lo + 1:r + 1])
        k, level = (lo + int(ch[-1]), 0.0) if ch.size else (r - 1, h)
    else:
        hi = int(np.searchsorted(t, t[r] + CROSS_SEARCH_S, side="right"))
        ch = np.flatnonzero(pos[r - 1:hi - 1] & ~pos[r:hi])
        k, level = (r - 1 + int(ch[0]), 0.0) if ch.size else (r - 1, h)
    y0, y1 = tq[k] - level, tq[k + 1] - level
    return float(t[k] + (t[k + 1] - t[k]) * (-y0) / (y1 - y0)) if y1 != y0 else float(t[k])


def _span(tc: float, half: float, side: int) -> tuple[float, float]:
    """``tc ± half`` (``side`` 0), or ``2 half`` after (+1) / before (-1) ``tc``: the ramp side of a coast."""
    return {0: (tc - half, tc + half), 1: (tc, tc + 2 * half), -1: (tc - 2 * half, tc)}[side]


def _rate(t: FloatArray, tq: FloatArray, tc: float, r: int, half: float, side: int) -> float:
    """Least-squares slope (N m/s) over :func:`_span`, at least the two samples around ``r``."""
    a, b = _span(tc, half, side)
    lo = min(int(np.searchsorted(t, a)), r - 1)
    hi = max(int(np.searchsorted(t, b, side="right")), r + 1)
    if hi - lo < 2:
        return float("nan")
    return float(np.polyfit(t[lo:hi] - tc, tq[lo:hi], 1)[0])


def _against_share(t: FloatArray, tq: FloatArray, span: tuple[float, float], sign: float) -> float:
    """Share of the torque's travel over ``span`` (s) that goes against ``sign``."""
    m = (t >= span[0]) & (t <= span[1])
    d = np.diff(tq[m]) * sign
    travel = float(np.abs(d).sum())
    return float(-d[d < 0].sum() / travel) if travel > 0 else 0.0


def find_reversals(t: FloatArray, tq: FloatArray, p: ReversalParams) -> tuple[list[Reversal], int]:
    """Driver reversals of the torque ``tq`` (N m) at times ``t`` (s); and how many changes were ringing."""
    h = p.hysteresis_nm
    driving = tq > h
    flips = np.flatnonzero(driving[1:] != driving[:-1]) + 1
    state = bool(driving[0])
    out: list[Reversal] = []
    ringing = 0
    for r in (int(i) for i in flips):
        new = bool(driving[r])
        if new == state:
            continue  # a short excursion already ignored
        t_r = float(t[r])
        holds = held = True
        if p.min_dwell_s > 0:
            holds = _share(t, driving, t_r, min(t_r + p.min_dwell_s, float(t[-1])), new) >= HOLD_SHARE
            held = _share(t, driving, max(t_r - p.min_dwell_s, float(t[0])), t_r, state) >= PRIOR_SHARE
        if not holds:
            ringing += 1
            continue
        state = new
        if not held:
            ringing += 1
            continue
        tip_in = new
        sign = 1.0 if tip_in else -1.0
        tc = _crossing(t, tq, r, tip_in, h)
        lo_t = (t_r - p.min_dwell_s, t_r) if tip_in else (t_r, t_r + p.min_dwell_s)
        low_side = tq[(t >= lo_t[0]) & (t < lo_t[1])] if tip_in else tq[(t >= lo_t[0]) & (t <= lo_t[1])]
        from_coast = bool(low_side.size == 0 or float(np.median(low_side)) >= -h)
        one_sided = (1 if tip_in else -1) if from_coast else 0
        rate = _rate(t, tq, tc, r, p.rate_half_window_s, one_sided)
        against = _against_share(t, tq, _span(tc, p.rate_half_window_s, one_sided), sign)
        if not sign * rate > 0 or against > p.max_ramp_reversal:
            ringing += 1
            continue
        out.append(Reversal(tip_in, tc, r, rate, from_coast))
    return out, ringing
