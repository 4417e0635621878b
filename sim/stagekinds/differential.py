"""``differential``: ``type = "open"`` (pinions and side gears, a coupling with lash) or ``"solid"`` (an axle).

A solid axle adds no coupling: its inertia joins the ring gear's body and the shafts start there.
An open differential ahead of two unequal half-shafts becomes a 3-body coupling (the case drives
both side gears, its deflection against their mean); the half-shaft stage builds it
(:mod:`sim.stagekinds.halfshaft`) from what :meth:`Differential.wire` leaves in ``pending``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

from sim.errors import ParameterError
from sim.stagekinds.base import DIFFERENTIAL, KindDoc, StageKind, Wiring

if TYPE_CHECKING:
    from sim.stages import Stage

TYPES = ("open", "solid")
_GEAR_FIELDS = ("stiffness", "damping", "lash_rad", "cubic_stiffness")


class Differential(StageKind):
    name = "differential"
    order = 50
    role = DIFFERENTIAL
    required = ("inertia",)
    optional = ("type", "stiffness", "damping", "lash_rad", "cubic_stiffness")
    reference_stage = "differential"
    doc = KindDoc('`type = "open"` (default): pinions and side gears; `type = "solid"`: a solid axle, no coupling',
                  "1", "kept", "none")

    def extra_required(self, raw: Mapping[str, Any]) -> tuple[str, ...]:
        return ("stiffness", "damping") if raw.get("type", "open") == "open" else ()

    def prepare(self, raw: Mapping[str, Any], data: dict[str, Any], label: str) -> None:
        if "type" in data and data["type"] not in TYPES:
            raise ParameterError(f"{label}type", data["type"], f"must be one of {list(TYPES)}")
        if data.get("type") == "solid":
            extra = next((k for k in _GEAR_FIELDS if k in data), None)
            if extra is not None:
                raise ParameterError(f"{label}{extra}", data[extra],
                                     "a solid axle has no differential gears; remove it")

    def written_fields(self, s: Stage) -> tuple[str, ...]:
        fields = super().written_fields(s)
        return tuple(k for k in fields if k in ("inertia", "type")) if s.type == "solid" else fields

    def has_coupling(self, s: Stage) -> bool:
        return s.type != "solid"

    def wire(self, w: Wiring, s: Stage, body_name: str, coupling_name: str) -> None:
        if not self.has_coupling(s):  # solid axle: the shafts start at the ring gear's body
            w.bld.inertia[w.cur] += s.inertia
        elif w.split:  # 3-body coupling, built with the unequal shafts
            w.pending["differential"] = s
        else:
            super().wire(w, s, body_name, coupling_name)


KIND = Differential()
