"""Generic machinery behind the vehicle description: field rules, validation, dict <-> dataclass.

Every numeric field of the frozen dataclasses in :mod:`sim.params` carries its unit and a rule
in its field metadata (:func:`num`); :func:`check` turns a violation into a
:class:`~sim.errors.ParameterError` naming the dotted field (``"halfshaft.stiffness"``) and the
offending value. :func:`build` constructs a dataclass tree from plain nested dicts (TOML/JSON),
:func:`to_plain` gives the same dicts back.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping
from dataclasses import field
from typing import Any, TypeVar

from sim.errors import ParameterError

# Constraint tags used in field metadata.
POS = "positive"
NONNEG = "nonnegative"
ANY = "finite"
INT_POS = "integer >= 1"
BOOL = "bool"

T = TypeVar("T")
NestedType = Callable[[type, str], "type | None"]
Preprocess = Callable[[type, Mapping[str, Any], str], Mapping[str, Any]]


Limits = tuple[float, float]


def num(unit: str, rule: str = POS, default: Any = dataclasses.MISSING, limits: Limits | None = None) -> Any:
    """A dataclass field with its unit, validation rule and physical ``limits`` (inclusive) in the metadata.

    ``limits`` bound what a real driveline can have; they keep a typo such as ``1e30`` from
    reaching the integrator, whose step follows the stiffest mode (docs/simulation.md lists them).
    """
    meta: dict[str, Any] = {"unit": unit, "rule": rule}
    if limits is not None:
        meta["limits"] = limits
    return field(default=default, metadata=meta)


def flag(default: bool = False) -> Any:
    """A boolean switch field."""
    return field(default=default, metadata={"unit": "-", "rule": BOOL})


def check(path: str, value: Any, rule: str, limits: Limits | None = None, unit: str = "") -> None:
    """Raise :class:`ParameterError` naming ``path`` if ``value`` breaks ``rule`` or lies outside ``limits``."""
    if rule == BOOL:
        if not isinstance(value, bool):
            raise ParameterError(path, value, "must be true or false")
        return
    if isinstance(value, tuple):
        for i, v in enumerate(value):
            check(f"{path}[{i}]", v, rule, limits, unit)
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
    if limits is not None and not limits[0] <= value <= limits[1]:
        raise ParameterError(path, value, f"outside the physical range [{limits[0]:g}, {limits[1]:g}] {unit}".rstrip())


def validate(obj: Any, prefix: str, extra: Callable[[Any, str], None] | None = None) -> None:
    """Check every ruled field of a dataclass tree; ``extra(obj, prefix)`` adds cross-field checks."""
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        path = f"{prefix}{f.name}"
        if "rule" in f.metadata:
            check(path, value, f.metadata["rule"], f.metadata.get("limits"), f.metadata.get("unit", ""))
        elif dataclasses.is_dataclass(value):
            validate(value, path + ".", extra)
    if extra is not None:
        extra(obj, prefix)


def to_plain(obj: Any) -> Any:
    """Nested dicts and lists (tuples become lists) of a dataclass tree."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name)) for f in dataclasses.fields(obj)}
    if isinstance(obj, tuple):
        return [to_plain(v) for v in obj]
    if isinstance(obj, Mapping):
        return {k: to_plain(v) for k, v in obj.items()}
    return obj


def _coerce(path: str, value: Any, f: dataclasses.Field[Any]) -> Any:
    rule = f.metadata.get("rule")
    if isinstance(f.default, tuple) or f.name == "teeth":
        if not isinstance(value, list | tuple) or len(value) != 4:
            raise ParameterError(path, value, "must be a list of 4 numbers")
        return tuple(value)
    if rule in (POS, NONNEG, ANY) and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    return value


def band(path: str, value: Any) -> tuple[float, float]:
    """A ``[min, max]`` pair as floats (validated later against the field it belongs to)."""
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise ParameterError(path, value, "must be [min, max]")
    try:
        return float(value[0]), float(value[1])
    except (TypeError, ValueError) as exc:
        raise ParameterError(path, value, "must be two numbers") from exc


def field_meta(cls: type, path: str, nested: NestedType) -> Mapping[str, Any] | None:
    """Metadata (unit, rule, limits) of the numeric field at dotted ``path`` below ``cls``, or None."""
    parts = path.split(".")
    for part in parts[:-1]:
        sub = nested(cls, part)
        if sub is None:
            return None
        cls = sub
    for f in dataclasses.fields(cls):
        if f.name == parts[-1]:
            return f.metadata if "rule" in f.metadata else None
    return None


def build(cls: type[T], data: Mapping[str, Any], prefix: str, nested: NestedType, pre: Preprocess) -> T:
    """Construct ``cls`` from a plain dict, recursing into nested tables.

    ``nested(cls, name)`` gives the dataclass of a sub-table (or None); ``pre(sub, value, path)``
    may rewrite a sub-table before it is built (unit conversions, shorthand forms).
    """
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
        sub = nested(cls, name)
        if sub is not None:
            value = pre(sub, value, path + ".")
            if not isinstance(value, Mapping):
                raise ParameterError(path, value, "must be a table")
            kwargs[name] = build(sub, value, path + ".", nested, pre)
        elif name == "stages":  # already built and checked by sim.stages
            kwargs[name] = tuple(value)
        elif name == "tolerances":
            if not isinstance(value, Mapping):
                raise ParameterError(path, value, "must be a table of [min, max]")
            kwargs[name] = {k: band(f"{path}.{k}", v) for k, v in value.items()}
        else:
            kwargs[name] = _coerce(path, value, f)
    try:
        return cls(**kwargs)
    except TypeError as exc:  # wrong types reaching the constructor
        raise ParameterError(prefix.rstrip(".") or "vehicle", data, str(exc)) from exc
