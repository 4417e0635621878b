"""What a stage kind is: its fields, its checks, how it wires into the compiled chain, its docs line.

A kind is one module in :mod:`sim.stagekinds` defining ``KIND = <StageKind subclass>()``; the
package finds it (no list to edit). The class says

- which fields a ``[[stage]]`` table of the kind takes (:attr:`StageKind.required`,
  :attr:`StageKind.optional`; units and limits are those of :class:`sim.stages.Stage`), and any
  check beyond the field limits (:meth:`StageKind.prepare`);
- where it may stand in the chain (:attr:`StageKind.role`: drive stages, then at most one
  differential, then at most one set of half-shafts);
- how it joins the body before it to a new body in the kernel's arrays (:meth:`StageKind.wire`,
  by default a coaxial or geared coupling with the kind's ratio, housing reaction and lash);
- which stage of the ``paper`` preset a stage of the kind is compared with when the service
  names a suspect field (:attr:`StageKind.reference_stage`);
- its row of the stage table in docs/simulation.md (:attr:`StageKind.doc`).

:class:`ChainBuilder` and :class:`Wiring` are the builder's state a kind's :meth:`wire` appends to
(``sim.model.build_chain`` runs them); everything here works on plain values, so this module
imports nothing of the vehicle description.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

from sim.errors import ParameterError
from sim.fields import INT_POS, POS, check
from sim.params_base import TEETH

if TYPE_CHECKING:
    from sim.stages import Stage

DRIVE, DIFFERENTIAL, SHAFTS = "drive", "differential", "shafts"  # roles, in chain order
STAGE_RATIO = (0.1, 30.0)  # one stage's speed ratio input / output
Row = tuple[str, int, int, int, float, float, float, float, float, float, float]  # see ChainBuilder.couple


@dataclass(frozen=True)
class KindDoc:
    """The kind's row of the stage table (docs/simulation.md, "Driveline topology")."""

    what: str
    ratio: str
    direction: str
    reaction: str


class ChainBuilder:
    """Bodies and coupling rows appended in chain order."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.inertia: list[float] = []
        self.rows: list[Row] = []
        self.gaps: dict[str, int] = {}

    def body(self, name: str, inertia: float) -> int:
        self.names.append(name)
        self.inertia.append(inertia)
        return len(self.names) - 1

    def couple(self, name: str, a: int, b: int, r: float, e: float, k: float, c: float, half: float,
               report: float, k3: float, b2: int = -1, gap: str = "") -> None:
        """Coupling a -> b (and b2) with values in a's angle; ``gap`` names the lash it carries."""
        if gap:
            self.gaps[gap] = len(self.rows)
        self.rows.append((name, a, b, b2, r, e, k, c, half, report, k3))

    def shaft(self, name: str, a: int, wheel_name: str, wheel_j: float, n: int, k: float, c: float, j: float,
              lash: float, k3: float, seg: int, gap: str) -> int:
        """``seg`` equal pieces from body ``a`` to a new wheel body; ``n`` equal shafts lumped in parallel."""
        j_seg = n * j / seg
        self.inertia[a] += 0.5 * j_seg
        nodes = [a, *(self.body(f"{name}_node{i}", j_seg)
                      for i in range(1, seg))]
        w = self.body(wheel_name, wheel_j + 0.5 * j_seg)
        nodes.append(w)
        for i in range(seg):  # seg pieces in series each deflect x/seg: k -> k seg, k3 -> k3 seg^3
            self.couple(name if seg == 1 else f"{name}{i + 1}", nodes[i], nodes[i + 1], 1.0, 0.0, n * k * seg,
                        n * c * seg, lash / 2 if i == 0 else 0.0, 1.0 / n, n * k3 * seg**3, gap=gap if i == 0 else "")
        return w


@dataclass
class Wiring:
    """The chain being built, stage by stage from the rotor (``sim.model.build_chain`` fills the ends)."""

    bld: ChainBuilder
    cur: int  # the body the next stage starts from
    driven_wheels: int  # shafts (and wheels) the last stage drives
    wheel_inertia: float  # own inertia of one wheel
    vehicle_inertia: float  # M R^2 in wheel angle; 0 when tyre slip makes the vehicle its own body
    split: bool  # unequal half-shafts follow: the differential is a 3-body coupling built with them
    sense: float = 1.0  # true turning sense of body ``cur`` in the rotor's frame
    wheel: int = -1  # wheel body once the shafts are built
    wheel2: int = -1  # the right wheel with unequal shafts
    own: float = 0.0  # wheel inertia carried by the wheel body (all driven wheels, or one with unequal shafts)
    pending: dict[str, Any] = field(default_factory=dict)  # what a stage leaves to a later one (the 3-body diff)


class StageKind:
    """One kind of driveline stage. Subclass, set the class attributes, override what differs."""

    name: ClassVar[str]
    order: ClassVar[int]  # position in the docs table and in messages listing the kinds
    aliases: ClassVar[tuple[str, ...]] = ()
    role: ClassVar[str] = DRIVE
    required: ClassVar[tuple[str, ...]] = ("stiffness", "damping", "inertia")
    optional: ClassVar[tuple[str, ...]] = ("lash_rad", "cubic_stiffness")
    geared: ClassVar[bool] = False  # takes ``ratio`` or ``teeth``
    reverses: ClassVar[bool] = False  # the output turns the other way from the input
    reference_stage: ClassVar[str] = "spline"  # the paper preset's stage of the same kind (vehicle check)
    doc: ClassVar[KindDoc]

    # ---- reading ----------------------------------------------------------------------------
    def fields(self) -> tuple[str, ...]:
        return ("kind", "name", *self.required, *self.optional)

    def extra_required(self, raw: Mapping[str, Any]) -> tuple[str, ...]:
        """Fields required beyond :attr:`required` for this table (they may depend on its other fields)."""
        return ()

    def prepare(self, raw: Mapping[str, Any], data: dict[str, Any], label: str) -> None:
        """Kind-specific checks of the table ``raw`` once its fields are known; may set derived values in ``data``."""
        if self.geared:
            data["ratio"] = self.ratio_of(raw, label)

    def ratio_from_teeth(self, teeth: tuple[int, int]) -> float:
        return teeth[1] / teeth[0]

    def ratio_of(self, raw: Mapping[str, Any], label: str) -> float:
        """The speed ratio from ``ratio`` or ``teeth``."""
        if ("ratio" in raw) == ("teeth" in raw):
            raise ParameterError(f"{label}ratio", raw.get("ratio"), "give exactly one of ratio or teeth")
        if "ratio" in raw:
            value = raw["ratio"]
            check(f"{label}ratio", value, POS, STAGE_RATIO)
            return float(value)
        teeth = raw["teeth"]
        if not isinstance(teeth, list | tuple) or len(teeth) != 2:
            raise ParameterError(f"{label}teeth", teeth, "must be [drive, driven] (planetary: [sun, ring])")
        check(f"{label}teeth", tuple(teeth), INT_POS, TEETH)
        ratio = self.ratio_from_teeth((teeth[0], teeth[1]))
        check(f"{label}teeth", ratio, POS, STAGE_RATIO, "(speed ratio)")
        return ratio

    def written_fields(self, s: Stage) -> tuple[str, ...]:
        """The fields :func:`sim.stages.stage_dict` writes back for ``s`` (``teeth`` is written as ``ratio``)."""
        return tuple(k for k in (*self.required, *self.optional) if k not in ("teeth", "right"))

    # ---- the model --------------------------------------------------------------------------
    def has_coupling(self, s: Stage) -> bool:
        """False when the stage adds no spring (a solid axle): no body, no gap."""
        return True

    def has_gap(self, s: Stage) -> bool:
        """Whether the stage carries a lash gap (what-ifs, tolerance bands and gap events name it)."""
        return self.has_coupling(s)

    def housing_reaction(self, sense: float, r: float) -> float:
        """``e``: the housing's share of the coupling torque (0: coaxial, no reaction on the housing)."""
        return 0.0

    def driven_wheels(self, s: Stage) -> int:
        """Wheels the stage drives when it is the last one (the half-shafts: their count)."""
        return 1

    def wire(self, w: Wiring, s: Stage, body_name: str, coupling_name: str) -> None:
        """Append the stage's body and coupling to the chain (values converted to the input shaft's angle).

        Stiffness and damping / f^2, cubic stiffness / f^4, lash * f, with f the stage ratio when
        they are stated on the output shaft (:attr:`sim.stages.Stage.to_input`).
        """
        f, r = s.to_input, s.ratio
        e = self.housing_reaction(w.sense, r)
        nxt = w.bld.body(body_name, s.inertia)
        w.bld.couple(coupling_name, w.cur, nxt, r, e, s.stiffness / f**2, s.damping / f**2,
                     s.lash_rad.nominal * f / 2, r, s.cubic_stiffness / f**4, gap=s.name if self.has_gap(s) else "")
        if self.reverses:
            w.sense = -w.sense
        w.cur = nxt

    # ---- docs -------------------------------------------------------------------------------
    def doc_row(self) -> str:
        """The kind's row of the stage table in docs/simulation.md."""
        names = f"`{self.name}`" + (f" (alias {', '.join(f'`{a}`' for a in self.aliases)})" if self.aliases else "")
        d = self.doc
        return f"| {names} | {d.what} | {d.ratio} | {d.direction} | {d.reaction} |"
