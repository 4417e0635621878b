"""Which second effects to fit with the best single one: a linearised screen of its remainder.

A partner ranked by its own single fit misses the effect whose signature only shows once the
first one is in: a drag under a large tyre-slip gap fits to "off" alone (it cannot touch a gap
that size) and would never be tried. The screen asks each candidate instead what it could do
*on top of* the best single fit, to first order (a score test, as in Gauss-Newton's first step):

- the calibration residual ``r0`` of the best single fit, and one simulator pass per nuisance and
  per candidate parameter, each moved by a finite step from the fitted (nuisance) or ``off``
  (candidate) value, give the columns of a Jacobian ``J``;
- a bounded linear least-squares fit of ``r0 + J a`` over the nuisance columns alone, and over the
  nuisance columns plus the candidate's, gives the energy the candidate removes beyond what the
  nuisance parameters remove anyway (``gain``), and the candidate's parameter values at that
  linear solution. The pair's nonlinear fit starts from the best of that point and two points a
  third and a tenth of the way there from ``off``: an effect as stiff near ``off`` as a cubic shaft
  hardening under a large wind-up is far from linear over a quarter of its range (on one drive a
  hardening of 3 % of the prior raised the residual 55-fold).

Only calibration events are used. Cost: one pass per parameter (about 15 passes for the library),
against up to about 70 for each pair fit it saves.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.calibrate import Bounds, FitResult, linear_cost
from app.analysis.diagnosis.forward import (
    DiagEvent,
    EffectSetting,
    Nuisance,
    prediction,
    simulate_events,
    vehicle_with,
    weighted_residual,
)
from sim import Vehicle
from sim.effects import get_effect
from sim.errors import SimError

FloatArray = npt.NDArray[np.float64]

STEP_FRACTION = 0.25  # a candidate parameter's probe step, as a share of its prior range
NUISANCE_STEPS = {"gain": 0.01, "grade_pct": 0.25, "offset_s": 0.002}  # probe steps of the nuisance parameters
STEP_SHARES = (1.0, 0.3, 0.1)  # pair-fit starts: these shares of the linear solution's move from ``off``


@dataclass(frozen=True)
class PartnerScreen:
    """Linearised gain of one candidate on top of the best single fit.

    Attributes
    ----------
    id : candidate effect id.
    gain : calibration chi2 (noise units) the candidate removes to first order beyond the nuisance.
    starts : its parameter values at the linear solution and part of the way there from ``off``
        (``STEP_SHARES``): start points for the pair fit.
    """

    id: str
    gain: float
    starts: tuple[dict[str, float], ...] = ()

    def describe(self) -> str:
        return f"{self.id} {self.gain:.1f}"


def residual_at(base: Vehicle, events: Sequence[DiagEvent], nui: Nuisance, settings: Sequence[EffectSetting],
                model: str) -> FloatArray | None:
    """The weighted residual of every event, in order, at fixed nuisance (offset included) and effect settings: one
    simulator pass (non-finite values as 0); None when the simulator rejects the parameters. The speed only: no
    gap states (the same speed, :func:`~.forward.simulate_events` with ``gaps=False``)."""
    try:
        veh = vehicle_with(base, nui, settings)
        outs = simulate_events(events, veh, nui.gain, settings, model, gaps=False)
    except SimError:
        return None
    r = np.concatenate([weighted_residual(ev, prediction(ev, out, nui.offset_s))
                        for ev, out in zip(events, outs, strict=True)])
    return np.asarray(np.nan_to_num(r, nan=0.0, posinf=0.0, neginf=0.0), dtype=np.float64)


def _coefficient_range(lo: float, hi: float, value: float, step: float) -> tuple[float, float]:
    """The range of a column's coefficient: a parameter at ``value`` probed by ``step`` stays within ``lo..hi`` (and
    the coefficient 0, no move, is always inside, for a value already past a bound)."""
    a, b = sorted(((lo - value) / step, (hi - value) / step))
    return min(a, 0.0), max(b, 0.0)


def screen_partners(base: Vehicle, events: Sequence[DiagEvent], first: FitResult, partners: Sequence[str],
                    model: str, bounds: Bounds | None = None) -> list[PartnerScreen]:
    """Linearised gain of each of ``partners`` on top of ``first`` on calibration ``events``, best first.

    ``bounds``: the nuisance parameters' bounds of the fits the screen stands for. With them, the nuisance columns
    move only as far as a fit could: a time offset the single fit left on its bound cannot take up more of a delay
    in the screen (a 20 ms torque lag beside a tyre's slip screened at 1 % of the partner threshold, the offset
    carrying the lag past its bound to first order)."""
    nui = first.nuisance
    settings = tuple(first.settings)
    r0 = residual_at(base, events, nui, settings, model)
    if r0 is None:
        return [PartnerScreen(c, 0.0) for c in partners]
    n_cols: list[FloatArray] = []
    n_lo: list[float] = []
    n_hi: list[float] = []
    for name, step in NUISANCE_STEPS.items():
        value = float(getattr(nui, name))
        if bounds is not None and value + step > getattr(bounds, name)[1]:
            step = -step  # probed away from the upper bound it sits on
        moved = residual_at(base, events, replace(nui, **{name: value + step}), settings, model)
        if moved is not None:
            n_cols.append(moved - r0)
            lo_a, hi_a = (-np.inf, np.inf)
            if bounds is not None:
                b_lo, b_hi = getattr(bounds, name)
                lo_a, hi_a = _coefficient_range(b_lo, b_hi, value, step)
            n_lo.append(lo_a)
            n_hi.append(hi_a)
    jn = np.column_stack(n_cols) if n_cols else np.zeros((r0.size, 0))
    nui_lo = np.array(n_lo, dtype=np.float64)
    nui_hi = np.array(n_hi, dtype=np.float64)
    cost_n, _ = linear_cost(r0, jn, nui_lo, nui_hi)
    out = []
    for cid in partners:
        eff = get_effect(cid)
        cols, lo, hi, steps = [], [], [], []
        off = {p.name: p.off for p in eff.params}
        for p in eff.params:
            span = p.hi - p.lo
            step = STEP_FRACTION * span * (1.0 if p.hi - p.off >= p.off - p.lo else -1.0)
            try:
                vals = eff.values({**off, p.name: p.off + step})
            except (SimError, ValueError):
                continue
            moved = residual_at(base, events, nui, (*settings, (eff, vals)), model)
            if moved is None:
                continue
            a_lo, a_hi = _coefficient_range(p.lo, p.hi, p.off, step)
            cols.append(moved - r0)
            lo.append(a_lo)
            hi.append(a_hi)
            steps.append((p, step))
        if not cols:
            out.append(PartnerScreen(cid, 0.0))
            continue
        jc = np.column_stack([jn, *cols])
        cost, a = linear_cost(r0, jc, np.concatenate([nui_lo, lo]), np.concatenate([nui_hi, hi]))
        moves = [(p, float(ak * step)) for (p, step), ak in zip(steps, a[jn.shape[1]:], strict=True)]
        starts = tuple({p.name: float(np.clip(p.off + share * move, p.lo, p.hi)) for p, move in moves}
                       for share in STEP_SHARES)
        out.append(PartnerScreen(cid, max(cost_n - cost, 0.0), starts))
    return sorted(out, key=lambda s: -s.gain)
