"""Vehicle description: frozen dataclasses with units, validation naming field and value.

A :class:`Vehicle` is read from TOML (:func:`sim.vehicle_file.load_vehicle`) or built from a
plain dict (:meth:`Vehicle.from_dict`); :meth:`Vehicle.to_dict` gives the same dict back, so
the service can store vehicles as TOML or JSON. Every numeric field carries its unit and a
constraint in the dataclass field metadata; :func:`_check` turns a violation into a
:class:`~sim.errors.ParameterError` naming the dotted field (``"halfshaft.stiffness"``) and
the offending value.

Angles are radians, torques N m, inertias kg m^2, stiffness N m/rad, damping N m s/rad.
Each backlash is the **total** clearance (2 alpha) measured in its own shaft's angle.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, TypeVar

from sim.errors import ParameterError

# Constraint tags used in field metadata.
POS = "positive"
NONNEG = "nonnegative"
ANY = "finite"
INT_POS = "integer >= 1"


def _f(unit: str, rule: str = POS, default: Any = dataclasses.MISSING) -> Any:
    return field(default=default, metadata={"unit": unit, "rule": rule})


@dataclass(frozen=True, kw_only=True)
class Motor:
    rotor_inertia: float = _f("kg m^2")
    viscous_damping: float = _f("N m s/rad", NONNEG, 0.0)
    max_power_kw: float = _f("kW", POS, 160.0)


@dataclass(frozen=True, kw_only=True)
class Reducer:
    """Two-stage reducer: pinion 1 / gear 1 (input -> intermediate), pinion 2 / gear 2 (-> differential)."""

    teeth: tuple[int, int, int, int] = _f("-", INT_POS)
    normal_module_mm: tuple[float, float, float, float] = _f("mm", POS, (1.0, 1.0, 1.0, 1.0))
    input_shaft_inertia: float = _f("kg m^2")
    intermediate_inertia: float = _f("kg m^2")
    differential_inertia: float = _f("kg m^2")
    side_gears_inertia: float = _f("kg m^2")
    spline_stiffness: float = _f("N m/rad (motor angle)")
    spline_damping: float = _f("N m s/rad", NONNEG)
    mesh1_stiffness: float = _f("N m/rad (intermediate angle)")
    mesh1_damping: float = _f("N m s/rad", NONNEG)
    mesh2_stiffness: float = _f("N m/rad (differential angle)")
    mesh2_damping: float = _f("N m s/rad", NONNEG)
    diff_stiffness: float = _f("N m/rad (side-gear angle)")
    diff_damping: float = _f("N m s/rad", NONNEG)

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

    stiffness: float = _f("N m/rad")
    damping: float = _f("N m s/rad", NONNEG)
    inertia: float = _f("kg m^2", NONNEG, 0.0)
    segments: int = _f("-", INT_POS, 1)
    count: int = _f("-", INT_POS, 2)


@dataclass(frozen=True, kw_only=True)
class Wheel:
    inertia: float = _f("kg m^2")  # own rotational inertia of one driven wheel
    radius: float = _f("m")


@dataclass(frozen=True, kw_only=True)
class Body:
    """Vehicle body and road load."""

    mass: float = _f("kg")
    speed_kmh: float = _f("km/h", NONNEG, 0.0)
    rolling_resistance: float = _f("-", NONNEG, 0.0)
    drag_area: float = _f("m^2", NONNEG, 0.0)
    air_density: float = _f("kg/m^3", NONNEG, 1.2)
    grade_percent: float = _f("%", ANY, 0.0)
    brake_torque: float = _f("N m (at the wheels)", NONNEG, 0.0)


@dataclass(frozen=True, kw_only=True)
class Housing:
    """Drive-unit housing rolling on its mounts about an axis parallel to the shafts."""

    enabled: bool = field(default=True, metadata={"unit": "-", "rule": "bool"})
    inertia: float = _f("kg m^2", POS, 2.5)
    mount_stiffness: float = _f("N m/rad", POS, 8.0e4)
    mount_damping: float = _f("N m s/rad", NONNEG, 150.0)


@dataclass(frozen=True, kw_only=True)
class Gap:
    """Total clearance (2 alpha) in its own shaft's angle, rad, with its tolerance band."""

    nominal: float = _f("rad", NONNEG)
    min: float = _f("rad", NONNEG, -1.0)  # omitted (-1) -> same as nominal
    max: float = _f("rad", NONNEG, -1.0)

    def __post_init__(self) -> None:
        for side in ("min", "max"):
            if getattr(self, side) == -1.0:
                object.__setattr__(self, side, self.nominal)


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
class TorqueLag:
    """Air-gap torque = first-order lag (tau) of the CAN torque delayed by ``delay_s``. Off at zeros."""

    delay_s: float = _f("s", NONNEG, 0.0)
    tau_s: float = _f("s", NONNEG, 0.0)


@dataclass(frozen=True, kw_only=True)
class SpeedSensor:
    """Inverter speed signal: first-order filter, transport delay, sample-and-hold, quantisation. Off at zeros."""

    tau_s: float = _f("s", NONNEG, 0.0)
    delay_s: float = _f("s", NONNEG, 0.0)
    sample_s: float = _f("s", NONNEG, 0.0)
    resolution_rpm: float = _f("rpm", NONNEG, 0.0)


@dataclass(frozen=True, kw_only=True)
class Drag:
    """Extra rotor drag: Coulomb (bearing/seal/churning) plus viscous. Off at zeros."""

    coulomb_nm: float = _f("N m", NONNEG, 0.0)
    viscous_nms: float = _f("N m s/rad", NONNEG, 0.0)


@dataclass(frozen=True, kw_only=True)
class Effects:
    torque_lag: TorqueLag = field(default_factory=TorqueLag)
    speed_sensor: SpeedSensor = field(default_factory=SpeedSensor)
    drag: Drag = field(default_factory=Drag)


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
        _validate(self, "")
        for path, band in self.tolerances.items():
            value = self.get(path)  # raises ParameterError for unknown paths
            if not isinstance(value, int | float) or isinstance(value, bool):
                raise ParameterError(f"tolerances.{path}", band, "only numeric fields can have a band")
            if len(band) != 2 or not all(math.isfinite(b) for b in band) or band[0] > band[1]:
                raise ParameterError(f"tolerances.{path}", band, "must be [min, max] with min <= max")

    # ---- dict round trip -------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Plain nested dict (tuples as lists) that :meth:`from_dict` accepts; JSON/TOML friendly."""
        out = _to_plain(self)
        out["tolerances"] = {k: [float(a), float(b)] for k, (a, b) in self.tolerances.items()}
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Vehicle:
        if not isinstance(data, Mapping):
            raise ParameterError("vehicle", type(data).__name__, "must be a table/dict")
        return _build(cls, data, "")

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

        Example: ``v.with_changes({"gaps.halfshaft": 0.0, "body.mass": 2000.0})``.
        Keyword form uses ``__`` for dots: ``v.with_changes(body__mass=2000.0)``.
        """
        all_changes = dict(changes or {})
        all_changes.update({k.replace("__", "."): v for k, v in kw.items()})
        data = self.to_dict()
        for path, value in all_changes.items():
            parts = path.split(".")
            if parts[0] == "gaps" and len(parts) == 2:
                parts.append("nominal")
            self.get(".".join(parts[:-1]) if len(parts) > 1 else parts[0])  # validates prefix
            node: Any = data
            for p in parts[:-1]:
                node = node[p]
            if parts[-1] not in node:
                raise ParameterError(path, value, "no such vehicle field")
            node[parts[-1]] = list(value) if isinstance(value, tuple) else value
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


# ---- generic machinery -------------------------------------------------------------------
T = TypeVar("T")


def _check(path: str, value: Any, rule: str) -> None:
    if rule == "bool":
        if not isinstance(value, bool):
            raise ParameterError(path, value, "must be true or false")
        return
    if isinstance(value, tuple):
        for i, v in enumerate(value):
            _check(f"{path}[{i}]", v, rule)
        return
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ParameterError(path, value, "must be a number")
    if not math.isfinite(value):
        raise ParameterError(path, value, "must be finite")
    if rule == POS and value <= 0:
        raise ParameterError(path, value, "must be > 0")
    if rule == NONNEG and value < 0:
        raise ParameterError(path, value, "must be >= 0")
    if rule == INT_POS and (not isinstance(value, int) or value < 1):
        raise ParameterError(path, value, "must be an integer >= 1")


def _validate(obj: Any, prefix: str) -> None:
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        path = f"{prefix}{f.name}"
        if "rule" in f.metadata:
            _check(path, value, f.metadata["rule"])
        elif dataclasses.is_dataclass(value):
            _validate(value, path + ".")
    if isinstance(obj, Gap) and obj.min > obj.max:
        raise ParameterError(f"{prefix}min", obj.min, f"must be <= {prefix}max = {obj.max}")
    if isinstance(obj, Halfshaft) and obj.count > 2:
        raise ParameterError(f"{prefix}count", obj.count, "must be 1 or 2 driven half-shafts")


def _to_plain(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: _to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple):
        return [_to_plain(v) for v in obj]
    if isinstance(obj, Mapping):
        return {k: _to_plain(v) for k, v in obj.items()}
    return obj


def _coerce(path: str, value: Any, f: dataclasses.Field[Any]) -> Any:
    rule = f.metadata.get("rule")
    default = f.default
    if isinstance(default, tuple) or f.name == "teeth":
        if not isinstance(value, list | tuple) or len(value) != 4:
            raise ParameterError(path, value, "must be a list of 4 numbers")
        return tuple(value)
    if rule in (POS, NONNEG, ANY) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def _build(cls: type[T], data: Mapping[str, Any], prefix: str) -> T:
    fields = {f.name: f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ParameterError(f"{prefix}{unknown[0]}", data[unknown[0]], f"unknown field; known: {sorted(fields)}")
    kwargs: dict[str, Any] = {}
    for name, f in fields.items():
        path = f"{prefix}{name}"
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise ParameterError(path, None, "required field missing")
            continue
        value = data[name]
        sub = _nested_type(cls, name)
        if sub is Gap and isinstance(value, int | float) and not isinstance(value, bool):
            value = {"nominal": value}
        if sub is not None:
            if not isinstance(value, Mapping):
                raise ParameterError(path, value, "must be a table")
            kwargs[name] = _build(sub, value, path + ".")
        elif name == "tolerances":
            if not isinstance(value, Mapping):
                raise ParameterError(path, value, "must be a table of [min, max]")
            kwargs[name] = {k: _band(f"{path}.{k}", v) for k, v in value.items()}
        else:
            kwargs[name] = _coerce(path, value, f)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # wrong types reaching the constructor
        raise ParameterError(prefix.rstrip(".") or "vehicle", data, str(exc)) from exc


def _band(path: str, value: Any) -> tuple[float, float]:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ParameterError(path, value, "must be [min, max]")
    try:
        return float(value[0]), float(value[1])
    except (TypeError, ValueError) as exc:
        raise ParameterError(path, value, "must be two numbers") from exc


_NESTED: dict[str, type] = {
    "motor": Motor, "reducer": Reducer, "halfshaft": Halfshaft, "wheel": Wheel, "body": Body,
    "gaps": Gaps, "housing": Housing, "effects": Effects, "torque_lag": TorqueLag,
    "speed_sensor": SpeedSensor, "drag": Drag,
}


def _nested_type(cls: type, name: str) -> type | None:
    if cls is Gaps:
        return Gap
    return _NESTED.get(name) if name != "tolerances" else None
