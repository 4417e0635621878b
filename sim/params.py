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
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from sim.errors import ParameterError
from sim.fields import ANY, INT_POS, NONNEG, POS, build, check, field_meta, flag, to_plain, validate
from sim.fields import num as _f
from sim.optional import Drag, Effects, ProgressiveStiffness, SpeedSensor, TorqueLag, TyreSlip

# Physical limits (inclusive) of the description's fields; docs/simulation.md explains each.
INERTIA = (1e-6, 1e4)  # kg m^2: a small pinion .. a heavy-truck wheel set
STIFFNESS = (1.0, 1e9)  # N m/rad: a soft mount .. a steel gear mesh referred to a large gear
DAMPING = (0.0, 1e6)  # N m s/rad
MASS = (1.0, 1e5)  # kg
WHEEL_RADIUS = (0.05, 2.0)  # m
TEETH = (5, 500)
MODULE_MM = (0.1, 50.0)
RATIO = (0.5, 50.0)  # total reducer ratio
MAX_SEGMENTS = 20  # half-shaft segments: 20 carry its first modes; more only shrinks the step
SEGMENTS = (1, MAX_SEGMENTS)
LASH_RAD = (0.0, 0.2)  # total clearance in its own shaft's angle: 0.2 rad = 11.5 deg, far above any real joint
CONTACT_RADIUS_MM = (0.0, 1000.0)


@dataclass(frozen=True, kw_only=True)
class Motor:
    rotor_inertia: float = _f("kg m^2", limits=INERTIA)
    viscous_damping: float = _f("N m s/rad", NONNEG, 0.0, DAMPING)
    max_power_kw: float = _f("kW", POS, 160.0, (0.1, 5000.0))


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


MM_FIELDS = ("nominal_mm", "min_mm", "max_mm")


@dataclass(frozen=True, kw_only=True)
class Gap:
    """Total clearance (2 alpha) in its own shaft's angle, rad, with its tolerance band.

    ``radius_mm`` is the contact (pitch) radius at which the clearance is a circumferential
    arc: gear pairs the driven gear's pitch radius (the arc backlash is the same on both
    gears), splines their pitch radius. With it the gap can be given in mm of arc
    (``nominal_mm``, ``min_mm``, ``max_mm`` in the file, converted to rad on reading) and read
    back in mm (:meth:`arc_mm`). 0 means not given.
    """

    nominal: float = _f("rad", NONNEG, limits=LASH_RAD)
    min: float = _f("rad", NONNEG, -1.0, LASH_RAD)  # omitted (-1) -> same as nominal
    max: float = _f("rad", NONNEG, -1.0, LASH_RAD)
    radius_mm: float = _f("mm", NONNEG, 0.0, CONTACT_RADIUS_MM)

    def __post_init__(self) -> None:
        for side in ("min", "max"):
            if getattr(self, side) == -1.0:
                object.__setattr__(self, side, self.nominal)

    def arc_mm(self, angle_rad: float | None = None, *, name: str = "gap") -> float:
        """Circumferential clearance (mm) of ``angle_rad`` (default: the nominal) at ``radius_mm``.

        Raises ParameterError naming ``gaps.<name>.radius_mm`` when the radius is not given.
        """
        if self.radius_mm <= 0:
            raise ParameterError(f"gaps.{name}.radius_mm", self.radius_mm,
                                 "contact radius not given; needed for a clearance in mm")
        return (self.nominal if angle_rad is None else angle_rad) * self.radius_mm


def gap_from_mm(value: Mapping[str, Any], path: str) -> dict[str, Any]:
    """A gap table with ``nominal_mm``/``min_mm``/``max_mm`` rewritten to rad via ``radius_mm``."""
    out = dict(value)
    if not any(k in out for k in MM_FIELDS):
        return out
    radius = out.get("radius_mm")
    if radius is None:
        raise ParameterError(f"{path}radius_mm", None, "needed to give the gap in mm of circumferential clearance")
    check(f"{path}radius_mm", radius, POS)
    for key in MM_FIELDS:
        if key not in out:
            continue
        rad_key = key[:-3]
        mm = out.pop(key)
        if rad_key in out:
            raise ParameterError(f"{path}{key}", mm, f"give {rad_key} (rad) or {key} (mm), not both")
        check(f"{path}{key}", mm, NONNEG)
        out[rad_key] = mm / radius
    return out


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


@dataclass(frozen=True, kw_only=True)
class Vehicle:
    """A complete driveline description. Build with :func:`sim.load_vehicle` or :meth:`from_dict`."""

    name: str
    motor: Motor
    reducer: Reducer
    halfshaft: Halfshaft
    wheel: Wheel
    body: Body
    gaps: Gaps
    housing: Housing = field(default_factory=Housing)
    effects: Effects = field(default_factory=Effects)
    description: str = ""
    # dotted field -> (min, max): uncertain non-gap parameters for tolerance analysis
    tolerances: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    def __post_init__(self) -> None:
        validate(self, "", _cross_checks)
        for path, band in self.tolerances.items():
            value = self.get(path)  # raises ParameterError for unknown paths
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise ParameterError(f"tolerances.{path}", band, "only numeric fields can have a band")
            if len(band) != 2 or not all(math.isfinite(b) for b in band) or band[0] > band[1]:
                raise ParameterError(f"tolerances.{path}", band, "must be [min, max] with min <= max")
            meta = field_meta(Vehicle, path, _nested_type)
            if meta is not None:  # every sampled variant must be a valid vehicle
                for end, b in zip(("min", "max"), band, strict=True):
                    check(f"tolerances.{path}[{end}]", b, meta["rule"], meta.get("limits"), meta.get("unit", ""))

    # ---- dict round trip -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (tuples as lists) that :meth:`from_dict` accepts; JSON/TOML friendly."""
        out = to_plain(self)
        out["tolerances"] = {k: [float(a), float(b)] for k, (a, b) in self.tolerances.items()}
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Vehicle:
        if not isinstance(data, Mapping):
            raise ParameterError("vehicle", type(data).__name__, "must be a table/dict")
        return build(cls, data, "", _nested_type, _preprocess)

    # ---- dotted access and what-ifs ---------------------------------------------------
    def get(self, path: str) -> Any:
        """Value at a dotted path, e.g. ``"gaps.halfshaft.nominal"`` or ``"halfshaft.stiffness"``."""
        obj: Any = self
        for part in path.split("."):
            if not dataclasses.is_dataclass(obj) or part not in {f.name for f in dataclasses.fields(obj)}:
                raise ParameterError(path, part, "no such vehicle field")
            obj = getattr(obj, part)
        if isinstance(obj, Gap):
            return obj.nominal
        return obj

    def with_changes(self, changes: Mapping[str, Any] | None = None, **kw: Any) -> Vehicle:
        """A copy with dotted fields replaced; ``"gaps.<name>"`` sets that gap's nominal size.

        Example: ``v.with_changes({"gaps.halfshaft": 0.0, "body.mass": 2000.0})``. Gap sizes may
        also be set in mm of circumferential clearance: ``{"gaps.mesh2.nominal_mm": 0.1}``
        (needs the gap's ``radius_mm``).
        Keyword form uses ``__`` for dots: ``v.with_changes(body__mass=2000.0)``.
        """
        all_changes = dict(changes or {})
        all_changes.update({k.replace("__", "."): v for k, v in kw.items()})
        data = self.to_dict()
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
            if parts[0] == "gaps" and len(parts) == 3 and parts[2] in MM_FIELDS:
                self.get(".".join(parts[:2]))  # validates the gap name
                gap = data["gaps"][parts[1]]
                gap.pop(parts[2][:-3], None)  # converted with the (possibly changed) radius on rebuild
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
            _move_band(data["gaps"][name], getattr(self.gaps, name))
        return Vehicle.from_dict(data)

    @property
    def ratio(self) -> float:
        return self.reducer.ratio

    @property
    def motor_side_gaps(self) -> tuple[float, ...]:
        """Each gap's nominal total clearance referred to the motor angle (rad)."""
        r1, r2 = self.reducer.ratio1, self.reducer.ratio2
        mult = (1.0, r1, r1 * r2, r1 * r2, r1 * r2)
        return tuple(g * m for g, m in zip(self.gaps.nominal(), mult, strict=True))



    @property
    def gap_radii_mm(self) -> tuple[float, ...]:
        """Contact (pitch) radius of each gap, mm, in :data:`GAP_NAMES` order (0 = not given)."""
        return tuple(getattr(self.gaps, g).radius_mm for g in GAP_NAMES)

    @property
    def gaps_mm(self) -> tuple[float, ...]:
        """Each gap's nominal circumferential clearance, mm. Raises ParameterError if a radius is missing."""
        return tuple(getattr(self.gaps, g).arc_mm(name=g) for g in GAP_NAMES)

    @property
    def motor_angle_per_mm(self) -> tuple[float, ...]:
        """Motor angle (rad) one mm of each gap's circumferential clearance costs: ``k_i / r_i``.

        ``k_i`` is the speed ratio motor / gap shaft (1, r1, r1 r2, r1 r2, r1 r2), ``r_i`` the
        contact radius in mm. Raises ParameterError if a radius is missing.
        """
        r1, r2 = self.reducer.ratio1, self.reducer.ratio2
        mult = (1.0, r1, r1 * r2, r1 * r2, r1 * r2)
        return tuple(m / getattr(self.gaps, g).arc_mm(1.0, name=g) for m, g in zip(mult, GAP_NAMES, strict=True))


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


def _move_band(gap: dict[str, Any], old: Gap) -> None:
    """Carry a gap's tolerance band along when a what-if changes its nominal size (``gap`` is its dict).

    The band is kept (as before bands were checked) and only widened to take in the new
    nominal, so a removed or enlarged gap is still a valid description whose band contains
    its size. Values that are not numbers are left for validation to name.
    """
    if "nominal_mm" in gap:
        mm, radius = gap["nominal_mm"], gap.get("radius_mm", 0.0)
        if not (_is_num(mm) and _is_num(radius) and radius > 0):
            return
        new = mm / radius
    else:
        new = gap.get("nominal")
        if not _is_num(new):
            return
    gap["min"], gap["max"] = min(old.min, new), max(old.max, new)


def _is_num(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


_TABLES: dict[str, type] = {c.__name__: c for c in (
    Motor, Reducer, Halfshaft, Wheel, Body, Gaps, Gap, Housing, Effects, TorqueLag, SpeedSensor, Drag,
    ProgressiveStiffness, TyreSlip,
)}


def _nested_type(cls: type, name: str) -> type | None:
    """The dataclass of sub-table ``name`` of ``cls`` (from the field's annotation), or None."""
    for f in dataclasses.fields(cls):
        if f.name == name:
            return _TABLES.get(str(f.type))
    return None


def _preprocess(sub: type, value: Any, path: str) -> Any:
    """Gap shorthand (a bare number is the nominal) and gap sizes given in mm."""
    if sub is Gap and isinstance(value, int | float) and not isinstance(value, bool):
        return {"nominal": value}
    if sub is Gap and isinstance(value, Mapping):
        return gap_from_mm(value, path)
    return value


__all__ = [
    "ANY", "GAP_NAMES", "Body", "Drag", "Effects", "Gap", "Gaps", "Halfshaft", "Housing", "Motor",
    "ProgressiveStiffness", "Reducer", "SpeedSensor", "TorqueLag", "TyreSlip", "Vehicle", "Wheel",
]
