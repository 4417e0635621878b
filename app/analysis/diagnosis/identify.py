"""What the data identify of the chosen effect's parameters, and what they only identify together.

A fit can put an effect's values anywhere along a valley of equal residual: the lash split between
the reducer and the half-shaft when only their total shows in the gap-traverse time, an input lag
against an output filter in a greedy pair. :func:`.calibrate.trade_offs` finds such pairs from the
fit's Jacobian; this module turns them into the report's ``decision.identifiability`` and a
sentence of the reason, with the combination that *is* identified where the library knows it
(for ``backlash``: the total lash seen from the motor, in mrad at the rotor).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

from app.analysis.diagnosis.calibrate import FitResult
from app.analysis.diagnosis.decide import Decision
from app.identify.base import lash_mrad
from sim import Vehicle
from sim.effects import apply_effects


def _identified(fit: FitResult, vehicle: Vehicle, names: set[str]) -> dict[str, Any] | None:
    """The identified combination of a traded-off pair, where the library knows one."""
    if names == {"backlash.reducer_scale", "backlash.halfshaft_scale"} and "backlash" in fit.values:
        return {"name": "total motor-side lash", "unit": "mrad",
                "value": round(lash_mrad(apply_effects(vehicle, {"backlash": fit.values["backlash"]})), 4),
                "nominal": round(lash_mrad(vehicle), 4)}
    return None


def with_identifiability(decision: Decision, fits: Mapping[str, FitResult], vehicle: Vehicle) -> Decision:
    """``decision`` with ``details["identifiability"]`` and a reason sentence when its fit has trade-offs."""
    if not decision.top or decision.status not in ("explained", "partial", "ambiguous"):
        return decision
    fit = fits.get("+".join(decision.top))
    if fit is None or not fit.trade_offs:
        return decision
    items = []
    words = []
    for a, b, r in fit.trade_offs:
        ident = _identified(fit, vehicle, {a, b})
        items.append({"params": [a, b], "correlation": round(r, 4), "identified": ident})
        text = f"{a} and {b} trade off (correlation {r:+.2f}): the data do not separate them"
        if ident is not None:
            text += (f"; only the {ident['name']} is identified, {ident['value']:.2f} {ident['unit']} "
                     f"(nominal {ident['nominal']:.2f})")
        words.append(text)
    details = {**decision.details, "identifiability": items}
    return replace(decision, details=details, reason=f"{decision.reason}. {'; '.join(words)}")
