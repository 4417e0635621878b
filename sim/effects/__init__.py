"""Library of candidate unmodelled effects, one module each (see :mod:`sim.effects.base`).

``EFFECTS`` maps an effect id to its :class:`~sim.effects.base.Effect`; :func:`get_effect` raises
an error that lists the known ids. :func:`apply_effects` returns a vehicle with effect values set,
which is how a diagnosed effect becomes a new vehicle version.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

from sim import params
from sim.effects import (
    backlash,
    drag,
    housing_mount,
    progressive_stiffness,
    speed_sensor,
    torque_lag,
    tyre_slip,
)
from sim.effects.base import Effect, ParamSpec
from sim.errors import ParameterError


def _model_has(section: str) -> bool:
    """Whether the simulator's vehicle description has ``effects.<section>`` (newer model hooks)."""
    return section in {f.name for f in dataclasses.fields(params.Effects)}


EFFECTS: dict[str, Effect] = {
    e.id: e
    for e in (
        backlash.EFFECT,
        housing_mount.EFFECT,
        torque_lag.EFFECT,
        speed_sensor.EFFECT,
        drag.EFFECT,
        progressive_stiffness.EFFECT,
        tyre_slip.EFFECT,
    )
    if e.id not in ("progressive_stiffness", "tyre_slip") or _model_has(e.id)
}


def get_effect(effect_id: str) -> Effect:
    try:
        return EFFECTS[effect_id]
    except KeyError:
        raise ParameterError("effect", effect_id, f"unknown effect; known: {', '.join(EFFECTS)}") from None


def apply_effects(vehicle: Any, settings: Mapping[str, Mapping[str, float]]) -> Any:
    """``vehicle`` with each effect's parameter values applied (``{effect_id: {param: value}}``).

    Every effect's changes are computed from the same base ``vehicle`` and applied in one rebuild,
    so the result does not depend on the order of the effects. Effects that act on the input or
    output only cannot be stored in a vehicle and raise :class:`~sim.errors.ParameterError`;
    effects that do not apply to ``vehicle`` (:meth:`Effect.inapplicable`) change nothing.
    """
    changes: dict[str, Any] = {}
    for eid, values in settings.items():
        eff = get_effect(eid)
        if eff.vehicle_change is None:
            raise ParameterError(f"effects.{eid}", dict(values), "acts outside the vehicle; cannot be stored in it")
        if eff.inapplicable(vehicle):  # e.g. housing_mount on a chain without a housing: nothing to change
            continue
        changes.update(eff.vehicle_change(vehicle, eff.values(values)))
    return vehicle.with_changes(changes) if changes else vehicle


def applicable_effects(vehicle: Any) -> dict[str, str]:
    """Effect id -> "" when it applies to ``vehicle``, else the reason it does not."""
    return {eid: e.inapplicable(vehicle) for eid, e in EFFECTS.items()}


__all__ = ["EFFECTS", "Effect", "ParamSpec", "applicable_effects", "apply_effects", "get_effect"]
