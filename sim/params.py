"""Vehicle description: frozen dataclasses with units, validation naming field and value.

A :class:`Vehicle` is read from TOML (:func:`sim.vehicle_file.load_vehicle`) or built from a
plain dict (:meth:`Vehicle.from_dict`); :meth:`Vehicle.to_dict` gives the same dict back, so
the service can store vehicles as TOML or JSON. Every numeric field carries its unit and a
constraint in the dataclass field metadata; :func:`_check` turns a violation into a
:class:`~sim.errors.ParameterError` naming the dotted field (``"halfshaft.stiffness"``) and
the offending value.

Angles are radians, torques N m, inertias kg m^2, stiffness N m/rad, damping N m s/rad.
Each backlash is the **total** clearance (2 alpha) measured in its own shaft's angle; with its
contact radius (``radius_mm``) it may also be given and read as a circumferential clearance in
mm of arc (the paper's measure for comparing gear pairs and splines).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sim.errors import ParameterError
from sim.fields import ANY, INT_POS, NONNEG, POS, build, check, field_meta, flag, to_plain, validate
from sim.fields import num as _f
from sim.layout import classic_field, legacy_stages, stage_checks, stage_layout
from sim.model import ChainModel, build_chain
from sim.optional import Drag, Effects, ProgressiveStiffness, SpeedSensor, TorqueLag, TyreSlip
from sim.params_base import (
    DAMPING,
    INERTIA,
    MASS,
    MM_FIELDS,
    MODULE_MM,
    RATIO,
    SEGMENTS,
    STIFFNESS,
    TEETH,
    WHEEL_RADIUS,
    Gap,
    gap_from_mm,
    move_band,
)
from sim.stages import Shaft, Stage, check_topology, gap_table, parse_chain, split_ends, stage_dict


@dataclass(frozen=True, kw_only=True)
class Motor:
    rotor_inertia: float = _f("kg m^2", limits=INERTIA)
    viscous_damping: float = _f("N m s/rad", NONNEG, 0.0, DAMPING)
    max_power_kw: float = _f("kW", POS, 160.0, (0.1, 5000.0))
    coulomb_drag: float = _f("N m", NONNEG, 0.0, (0.0, 1e4))  # bearing/seal friction, tanh-smoothed at 1 rad/s
    # air-gap torque per N m of the logged torque: an inverter's torque estimate is often off by tens of percent;
    # the simulator multiplies the logged torque by it (an identified vehicle carries the fitted value)
    torque_gain: float = _f("-", POS, 1.0, (0.05, 20.0))


@dataclass(frozen=True, kw_only=True)
class Reducer:
    """Two-stage reducer: pinion 1 / gear 1 (input -> intermediate), pinion 2 / gear 2 (-> differential)."""

    teeth: tuple[int, int, int, int] = _f("-", INT_POS, limits=TEETH)
    normal_module_mm: tuple[float, float, float, float] = _f("mm", POS, (1.0, 1.0, 1.0, 1.0), MODULE_MM)
    input_shaft_inertia: float = _f("kg m^2", limits=INERTIA)
    intermediate_inertia: float = _f("kg m^2", limits=INERTIA)
    differential_inertia: float = _f("kg m^2", limits=INERTIA)
    side_gears_inertia: float = _f("kg m^2", limits=INERTIA)
    spline_stiffness: float = _f("N m/rad (motor angle)", limits=STIFFNESS)
    spline_damping: float = _f("N m s/rad", NONNEG, limits=DAMPING)
    mesh1_stiffness: float = _f("N m/rad (intermediate angle)", limits=STIFFNESS)
    mesh1_damping: float = _f("N m s/rad", NONNEG, limits=DAMPING)
    mesh2_stiffness: float = _f("N m/rad (differential angle)", limits=STIFFNESS)
    mesh2_damping: float = _f("N m s/rad", NONNEG, limits=DAMPING)
    diff_stiffness: float = _f("N m/rad (side-gear angle)", limits=STIFFNESS)
    diff_damping: float = _f("N m s/rad", NONNEG, limits=DAMPING)

    @property
    def ratio1(self) -> float:
        return self.teeth[1] / self.teeth[0]

    @property
    def ratio2(self) -> float:
        return self.teeth[3] / self.teeth[2]

    @property
    def ratio(self) -> float:
        """Total ratio motor speed / wheel speed."""
        return self.ratio1 * self.ratio2


@dataclass(frozen=True, kw_only=True)
class Halfshaft:
    """Per half-shaft values; ``count`` shafts (and driven wheels) act in parallel."""

    stiffness: float = _f("N m/rad", limits=STIFFNESS)
    damping: float = _f("N m s/rad", NONNEG, limits=DAMPING)
    inertia: float = _f("kg m^2", NONNEG, 0.0, (0.0, INERTIA[1]))
    segments: int = _f("-", INT_POS, 1, SEGMENTS)
    count: int = _f("-", INT_POS, 2, (1, 2))


@dataclass(frozen=True, kw_only=True)
class Wheel:
    inertia: float = _f("kg m^2", limits=INERTIA)  # own rotational inertia of one driven wheel
    radius: float = _f("m", limits=WHEEL_RADIUS)
    viscous_drag: float = _f("N m s/rad (per wheel)", NONNEG, 0.0, DAMPING)  # hub bearings, brake pads
    coulomb_drag: float = _f("N m (per wheel)", NONNEG, 0.0, (0.0, 1e4))  # tanh-smoothed at 0.05 rad/s


@dataclass(frozen=True, kw_only=True)
class Body:
    """Vehicle body and road load."""

    mass: float = _f("kg", limits=MASS)
    speed_kmh: float = _f("km/h", NONNEG, 0.0, (0.0, 500.0))
    rolling_resistance: float = _f("-", NONNEG, 0.0, (0.0, 0.5))
    drag_area: float = _f("m^2", NONNEG, 0.0, (0.0, 50.0))
    air_density: float = _f("kg/m^3", NONNEG, 1.2, (0.0, 5.0))
    grade_percent: float = _f("%", ANY, 0.0, (-100.0, 100.0))
    brake_torque: float = _f("N m (at the wheels)", NONNEG, 0.0, (0.0, 1e6))


@dataclass(frozen=True, kw_only=True)
class Housing:
    """Drive-unit housing rolling on its mounts about an axis parallel to the shafts."""

    enabled: bool = flag(True)
    inertia: float = _f("kg m^2", POS, 2.5, INERTIA)
    mount_stiffness: float = _f("N m/rad", POS, 8.0e4, STIFFNESS)
    mount_damping: float = _f("N m s/rad", NONNEG, 150.0, DAMPING)


@dataclass(frozen=True, kw_only=True)
class BodyPitch:
    """The sprung body pitching on its suspension, for the seat-rail acceleration (``sim.seat``). Off by default:
    the driveline model does not need it and the paper gives none of it. Heights above the road."""

    enabled: bool = flag(False)
    inertia: float = _f("kg m^2 (pitch, about the centre of gravity)", POS, 2500.0, (1.0, 1e6))
    frequency_hz: float = _f("Hz (pitch on the suspension)", POS, 1.3, (0.1, 10.0))
    damping_ratio: float = _f("-", NONNEG, 0.3, (0.0, 2.0))
    cg_height: float = _f("m", POS, 0.55, (0.05, 5.0))
    seat_rail_height: float = _f("m", NONNEG, 0.3, (0.0, 5.0))


GAP_NAMES: tuple[str, ...] = ("spline", "mesh1", "mesh2", "differential", "halfshaft")


@dataclass(frozen=True, kw_only=True)
class Gaps:
    spline: Gap
    mesh1: Gap
    mesh2: Gap
    differential: Gap
    halfshaft: Gap

    def nominal(self) -> tuple[float, ...]:
        return tuple(getattr(self, n).nominal for n in GAP_NAMES)


CONTACT_LAWS = ("limited", "full")  # Vehicle.contact_damping, the default first
MAX_NAME_CHARS = 200
MAX_DESCRIPTION_CHARS = 4000  # a note for people; a vehicle's summary (and every listing of vehicles) carries it


@dataclass(frozen=True, kw_only=True)
class Vehicle:
    """A complete driveline description. Build with :func:`sim.load_vehicle` or :meth:`from_dict`."""

    name: str
    motor: Motor
    wheel: Wheel
    body: Body
    # classic layout (two gear stages, differential, half-shafts) ...
    reducer: Reducer | None = None
    halfshaft: Halfshaft | None = None
    gaps: Gaps | None = None
    # ... or a chain of stages from rotor to wheels (sim.stages); exactly one of the two
    stages: tuple[Stage, ...] = ()
    housing: Housing = field(default_factory=Housing)
    effects: Effects = field(default_factory=Effects)
    body_pitch: BodyPitch = field(default_factory=BodyPitch)
    # how a contact's damper engages (sim.integrate): "limited" to the spring torque (Modelica's ElastoBacklash), or
    # "full" once in contact; an identification chooses between them on the log (app.identify.form)
    contact_damping: str = "limited"
    description: str = ""
    # dotted field -> (min, max): uncertain non-gap parameters for tolerance analysis
    tolerances: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        classic = (self.reducer, self.halfshaft, self.gaps)
        if self.stages and any(x is not None for x in classic):
            raise ParameterError("stage", len(self.stages), "give [[stage]] tables or [reducer]/[halfshaft]/[gaps.*], "
                                 "not both")
        if not self.stages:
            for name, x in zip(("reducer", "halfshaft", "gaps"), classic, strict=True):
                if x is None:
                    raise ParameterError(name, None, "required field missing (or describe the driveline as "
                                         "[[stage]] tables)")
        validate(self, "", _cross_checks)
        if self.contact_damping not in CONTACT_LAWS:
            raise ParameterError("contact_damping", self.contact_damping,
                                 f"must be one of {', '.join(repr(x) for x in CONTACT_LAWS)}")
        for text, limit in (("name", MAX_NAME_CHARS), ("description", MAX_DESCRIPTION_CHARS)):
            value = getattr(self, text)
            if not isinstance(value, str) or len(value) > limit:
                raise ParameterError(text, value, f"must be text of at most {limit} characters")
        if self.stages:
            check_topology(self.stages)
            stage_checks(self)
        for path, band in self.tolerances.items():
            value = self.get(path)  # raises ParameterError for unknown paths
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise ParameterError(f"tolerances.{path}", band, "only numeric fields can have a band")
            if len(band) != 2 or not all(math.isfinite(b) for b in band) or band[0] > band[1]:
                raise ParameterError(f"tolerances.{path}", band, "must be [min, max] with min <= max")
            parts = path.split(".")
            if parts[0] == "stage" and len(parts) >= 3:  # a stage field: its own metadata (right shaft: Shaft's)
                meta = field_meta(Shaft if parts[2] == "right" else Stage, parts[-1], _nested_type)
            else:
                meta = field_meta(Vehicle, path, _nested_type)
            if meta is not None:  # every sampled variant must be a valid vehicle
                for end, b in zip(("min", "max"), band, strict=True):
                    check(f"tolerances.{path}[{end}]", b, meta["rule"], meta.get("limits"), meta.get("unit", ""))

    # ---- dict round trip -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:  # by hand: the file format's round trip (from_dict), not a payload
        """Plain nested dict (tuples as lists) that :meth:`from_dict` accepts; JSON/TOML friendly."""
        out = to_plain(self)
        for key in ("reducer", "halfshaft", "gaps", "stages"):
            if not out[key]:
                out.pop(key)
        if self.contact_damping == CONTACT_LAWS[0]:  # the default law: files without the key read as before
            out.pop("contact_damping")
        if self.stages:
            out.pop("stages")
            out["stage"] = [stage_dict(s) for s in self.stages]
        out["tolerances"] = {k: [float(a), float(b)] for k, (a, b) in self.tolerances.items()}
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Vehicle:
        if not isinstance(data, Mapping):
            raise ParameterError("vehicle", type(data).__name__, "must be a table/dict")
        if "stage" not in data:
            if "stages" in data:
                raise ParameterError("stages", data["stages"], "unknown field; the chain is given as [[stage]]")
            return build(cls, data, "", _nested_type, _preprocess)
        data, first = split_ends(data)
        stages = parse_chain(data.pop("stage"), first)
        if "housing" not in data:  # stage files: no [housing] means no housing on mounts
            data["housing"] = {"enabled": False}
        return build(cls, {**data, "stages": stages}, "", _nested_type, _preprocess)

    # ---- dotted access and what-ifs ---------------------------------------------------
    def get(self, path: str) -> Any:
        """Value at a dotted path, e.g. ``"gaps.halfshaft.nominal"`` or ``"halfshaft.stiffness"``."""
        obj: Any = self
        parts = path.split(".")
        if self.stages and parts[0] in ("gaps", "stage") and len(parts) >= 2:
            obj = self.gap(parts[1]) if parts[0] == "gaps" else self.stage(parts[1])
            parts = parts[2:]
        for part in parts:
            if not dataclasses.is_dataclass(obj) or part not in {f.name for f in dataclasses.fields(obj)}:
                raise ParameterError(path, part, "no such vehicle field")
            obj = getattr(obj, part)
        if isinstance(obj, Gap):
            return obj.nominal
        return obj

    def with_changes(self, changes: Mapping[str, Any] | None = None, **kw: Any) -> Vehicle:
        """A copy with dotted fields replaced (no changes: this vehicle itself); ``"gaps.<name>"`` sets that gap's
        nominal size.

        Example: ``v.with_changes({"gaps.halfshaft": 0.0, "body.mass": 2000.0})``. Gap sizes may
        also be set in mm of circumferential clearance: ``{"gaps.mesh2.nominal_mm": 0.1}``
        (needs the gap's ``radius_mm``).
        Keyword form uses ``__`` for dots: ``v.with_changes(body__mass=2000.0)``.
        """
        all_changes = dict(changes or {})
        all_changes.update({k.replace("__", "."): v for k, v in kw.items()})
        if not all_changes:
            return self  # nothing to change: the same (frozen) vehicle, its compiled chain with it
        data = self.to_dict() | {"contact_damping": self.contact_damping}
        if self.stages:  # stage tables by name while editing
            data["stage"] = {s["name"]: s for s in data["stage"]}
        moved: set[str] = set()  # gaps whose nominal changed
        banded: set[str] = set()  # gaps whose min or max was given
        for path, value in all_changes.items():
            parts = path.split(".")
            if parts[0] == "gaps" and len(parts) == 2:
                parts.append("nominal")
            if parts[0] == "gaps" and len(parts) == 3 and parts[2] in ("nominal", "nominal_mm"):
                moved.add(parts[1])
            if parts[0] == "gaps" and len(parts) == 3 and parts[2] in ("min", "max", "min_mm", "max_mm"):
                banded.add(parts[1])
            if parts[0] == "gaps" and len(parts) == 3:
                self.gap(parts[1])  # validates the gap name
                gap = gap_table(data, parts[1])
                if parts[2] in MM_FIELDS:
                    gap.pop(parts[2][:-3], None)  # converted with the (possibly changed) radius on rebuild
                elif parts[2] not in gap:
                    raise ParameterError(path, value, "no such vehicle field")
                gap[parts[2]] = value
                continue
            self.get(".".join(parts[:-1]) if len(parts) > 1 else parts[0])  # validates prefix
            node: Any = data
            for p in parts[:-1]:
                node = node[p]
            if parts[-1] not in node:
                raise ParameterError(path, value, "no such vehicle field")
            node[parts[-1]] = list(value) if isinstance(value, tuple) else value
        for name in moved - banded:
            move_band(gap_table(data, name), self.gap(name))
        if self.stages:
            data["stage"] = list(data["stage"].values())
        return Vehicle.from_dict(data)

    # ---- the chain of stages (classic layouts are read as one) ------------------------
    @functools.cached_property
    def chain(self) -> tuple[Stage, ...]:
        """The driveline as stages from rotor to wheels; the classic layout as its five stages."""
        return self.stages or legacy_stages(self)

    @functools.cached_property
    def compiled(self) -> ChainModel:
        """The chain compiled into the kernel's arrays (:func:`sim.model.build_chain`), built on first use and
        kept: once per Vehicle object, read-only, shared by every simulation and analysis of this vehicle.
        A changed vehicle (:meth:`with_changes`) is a new object with its own."""
        return build_chain(self)

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the compiled chain (rebuilt on first use where it is unpickled)."""
        state = dict(self.__dict__)
        state.pop("compiled", None)
        return state

    def as_stages(self) -> Vehicle:
        """The same driveline written as a stage chain (a classic file converted; a chain unchanged)."""
        return self if self.stages else Vehicle.from_dict(stage_layout(self))

    def stage(self, name: str) -> Stage:
        """The stage called ``name`` (ParameterError naming the known ones otherwise)."""
        for s in self.chain:
            if s.name == name:
                return s
        raise ParameterError(f"stage.{name}", name, f"no such stage; known: {[s.name for s in self.chain]}")

    @property
    def gap_names(self) -> tuple[str, ...]:
        """Names of the backlash gaps in chain order (classic layout: :data:`GAP_NAMES`)."""
        return GAP_NAMES if not self.stages else tuple(g for s in self.stages for g in s.gap_names())

    def gap(self, name: str) -> Gap:
        """The gap ``name`` (a stage name, or ``<halfshaft stage>_right`` for an unequal right shaft)."""
        if not self.stages and self.gaps is not None and name in GAP_NAMES:
            gap: Gap = getattr(self.gaps, name)
            return gap
        for s in self.stages:
            if name in s.gap_names():
                return s.lash_rad if name == s.name or s.right is None else s.right.lash_rad
        raise ParameterError(f"gaps.{name}", name, f"no such gap; known: {list(self.gap_names)}")

    def gap_speed_ratio(self, name: str) -> float:
        """Motor speed / speed of the shaft the gap ``name`` is measured on."""
        k = 1.0
        for s in self.chain:
            if name in s.gap_names():
                return k * s.to_input
            k *= s.ratio
        raise ParameterError(f"gaps.{name}", name, f"no such gap; known: {list(self.gap_names)}")

    @property
    def has_housing(self) -> bool:
        return self.housing.enabled

    @property
    def housing_described(self) -> bool:
        """Whether the file describes a drive-unit housing on mounts: a classic layout always does (its
        ``[housing]`` may be switched off), a stage chain only where it has an enabled ``[housing]``."""
        return self.housing.enabled or not self.stages

    def field_of(self, stage: str, attr: str) -> str:
        """The dotted field holding stage ``stage``'s ``attr`` in this vehicle's own file layout: a stage chain's
        ``stage.<stage>.<attr>`` (``right.<attr>`` for an unequal right shaft), a classic file's section and key
        (:data:`sim.layout.CLASSIC_STAGES`; a cubic term in ``[effects.progressive_stiffness]``). Every reader
        of the vehicle outside the file format goes through :attr:`chain` and this, never through the
        classic sections."""
        if self.stages:
            self.stage(stage)  # validates the name
            return f"stage.{stage}.{attr}"
        return classic_field(stage, attr)

    @property
    def driven_wheels(self) -> int:
        last = self.chain[-1]
        return last.spec.driven_wheels(last)

    @property
    def ratio(self) -> float:
        """Total ratio motor speed / wheel speed (a classic file's is its two gear pairs': the other stages are 1,
        so the product is the reducer's exactly)."""
        return math.prod(s.ratio for s in self.chain)

    @property
    def motor_side_gaps(self) -> tuple[float, ...]:
        """Each gap's nominal total clearance referred to the motor angle (rad), in :attr:`gap_names` order."""
        return tuple(self.gap(g).nominal * self.gap_speed_ratio(g) for g in self.gap_names)

    @property
    def gap_radii_mm(self) -> tuple[float, ...]:
        """Contact (pitch) radius of each gap, mm, in :attr:`gap_names` order (0 = not given)."""
        return tuple(self.gap(g).radius_mm for g in self.gap_names)

    @property
    def gaps_mm(self) -> tuple[float, ...]:
        """Each gap's nominal circumferential clearance, mm. Raises ParameterError if a radius is missing."""
        return tuple(self.gap(g).arc_mm(name=g) for g in self.gap_names)

    @property
    def motor_angle_per_mm(self) -> tuple[float, ...]:
        """Motor angle (rad) one mm of each gap's circumferential clearance costs: ``k_i / r_i``.

        ``k_i`` is the speed ratio motor / gap shaft (classic: 1, r1, r1 r2, r1 r2, r1 r2), ``r_i``
        the contact radius in mm. Raises ParameterError if a radius is missing.
        """
        return tuple(self.gap_speed_ratio(g) / self.gap(g).arc_mm(1.0, name=g) for g in self.gap_names)


def _cross_checks(obj: Any, prefix: str) -> None:
    if isinstance(obj, Gap) and obj.min > obj.max:
        raise ParameterError(f"{prefix}min", obj.min, f"must be <= {prefix}max = {obj.max!r}")
    if isinstance(obj, Gap) and not obj.min <= obj.nominal <= obj.max:
        raise ParameterError(f"{prefix}nominal", obj.nominal,
                             f"must lie within its tolerance band [min, max] = [{obj.min!r}, {obj.max!r}] rad")
    if isinstance(obj, Reducer) and not RATIO[0] <= obj.ratio <= RATIO[1]:
        raise ParameterError(f"{prefix}teeth", list(obj.teeth),
                             f"total ratio {obj.ratio:.4g} outside the physical range [{RATIO[0]:g}, {RATIO[1]:g}]")
    if isinstance(obj, Halfshaft) and obj.count > 2:
        raise ParameterError(f"{prefix}count", obj.count, "must be 1 or 2 driven half-shafts")


_TABLES: dict[str, type] = {c.__name__: c for c in (
    Motor, Reducer, Halfshaft, Wheel, Body, Gaps, Gap, Housing, Effects, TorqueLag, SpeedSensor, Drag,
    ProgressiveStiffness, TyreSlip, BodyPitch,
)}


def _nested_type(cls: type, name: str) -> type | None:
    """The dataclass of sub-table ``name`` of ``cls`` (from the field's annotation), or None."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            return _TABLES.get(str(f.type).removesuffix(" | None"))
    return None


def _preprocess(sub: type, value: Any, path: str) -> Any:
    """Gap shorthand (a bare number is the nominal) and gap sizes given in mm."""
    if sub is Gap and isinstance(value, int | float) and not isinstance(value, bool):
        return {"nominal": value}
    if sub is Gap and isinstance(value, Mapping):
        return gap_from_mm(value, path)
    return value


__all__ = [
    "ANY", "GAP_NAMES", "Body", "BodyPitch", "Drag", "Effects", "Gap", "Gaps", "Halfshaft", "Housing", "Motor",
    "ProgressiveStiffness", "Reducer", "SpeedSensor", "TorqueLag", "TyreSlip", "Vehicle", "Wheel",
]
