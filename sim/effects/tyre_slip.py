"""``tyre_slip``: tyre longitudinal compliance and slip with a relaxation length.

With it the vehicle mass is its own body behind the tyres instead of being folded into the wheel
inertia (``effects.tyre_slip`` in the simulator): per driven tyre ::

    dF/dt = (C / sigma) (omega_w R - V) - (|V| / sigma) F

a spring ``C / sigma`` in series with a speed-dependent damper, which lowers the shuffle
frequency much like a softer half-shaft would (a prototype absorbed it as a 21-23 % lower shaft
stiffness). Parameters: the slip *compliance* ``1e6 / C`` (per MN of force per unit slip; 0 is a
rigid tyre, the model without the effect) and the relaxation length. Priors: C from 25 kN to
rigid, relaxation lengths 0.05-0.6 m.
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values

MIN_COMPLIANCE = 0.05  # below this (C above 20 MN per unit slip) the tyre is rigid for the driveline


def _applies(vehicle: Any) -> str:
    if any(s.right is not None for s in vehicle.chain):
        return "not modelled with unequal half-shafts (two wheel bodies)"
    return ""


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    if _applies(vehicle):
        return {}
    if v["compliance_per_mn"] < MIN_COMPLIANCE:
        return {"effects.tyre_slip.enabled": False}
    return {
        "effects.tyre_slip.enabled": True,
        "effects.tyre_slip.slip_stiffness": 1e6 / v["compliance_per_mn"],
        "effects.tyre_slip.relaxation_length": v["relaxation_m"],
    }


EFFECT = Effect(
    id="tyre_slip",
    title="Tyre longitudinal compliance and slip (relaxation length)",
    params=(
        ParamSpec("compliance_per_mn", "1/MN", 0.0, 40.0, 0.0, "slip compliance 1e6 / C, C in N per unit slip"),
        ParamSpec("relaxation_m", "m", 0.05, 0.6, 0.15, "tyre relaxation length"),
    ),
    vehicle_change=_changes,
    model="multibody",
    applies=_applies,
    order=70,
)
