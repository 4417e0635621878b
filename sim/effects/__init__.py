"""Library of candidate unmodelled effects, one module each (see :mod:`sim.effects.base`).

Every module of this package except :mod:`sim.effects.base` defines ``EFFECT``, an
:class:`~sim.effects.base.Effect` whose ``id`` is the module's name. The registry imports them all
when the package is first imported and orders them by ``(order, id)``: a new effect is one new
module here plus its test (docs/architecture.md, "Where an extension goes"). ``EFFECTS`` maps an
effect id to its :class:`~sim.effects.base.Effect`; :func:`get_effect` raises an error that lists
the known ids. :func:`apply_effects` returns a vehicle with effect values set, which is how a
diagnosed effect becomes a new vehicle version.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping
from typing import Any

from sim import params
from sim.effects.base import Effect, ParamSpec
from sim.errors import ParameterError
from sim.modules import module_entries


def _model_has(section: str) -> bool:
    """Whether the simulator's vehicle description has ``effects.<section>`` (newer model hooks)."""
    return section in {f.name for f in dataclasses.fields(params.Effects)}


# effects that act through an ``effects.<id>`` section of the vehicle description, listed only when the
# simulator has that section
_MODEL_HOOKS = ("progressive_stiffness", "tyre_slip")


def discover(package: str = __name__, path: Iterable[str] | None = None) -> dict[str, Effect]:
    """The effects defined by the modules of ``package`` (its ``path``), by id in ``(order, id)`` order.

    A module that defines no ``EFFECT``, or one whose id is not the module's name, is a ``TypeError``
    naming the file: a library entry is never skipped silently.
    """
    found = module_entries(package, path if path is not None else __path__, "EFFECT", Effect, lambda e: e.id,
                           "an Effect with id {!r}")
    found.sort(key=lambda e: (e.order, e.id))
    return {e.id: e for e in found if e.id not in _MODEL_HOOKS or _model_has(e.id)}


EFFECTS: dict[str, Effect] = discover()


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
    return vehicle.with_changes(changes)


def applicable_effects(vehicle: Any) -> dict[str, str]:
    """Effect id -> "" when it applies to ``vehicle``, else the reason it does not."""
    return {eid: e.inapplicable(vehicle) for eid, e in EFFECTS.items()}


__all__ = ["EFFECTS", "Effect", "ParamSpec", "applicable_effects", "apply_effects", "discover", "get_effect"]
