"""Dataclasses written as plain dicts (REST payloads, stored JSON, reports), declared instead of hand-written.

A dataclass that derives from :class:`Serial` gets ``to_dict``: one entry per field, in field order, keyed by the
field's name, the value written as :func:`dataclasses.asdict` writes it (nested dataclasses, lists, tuples and
dicts followed and copied, tuples kept as tuples; other values as they are), except that a nested object with a
``to_dict`` of its own is written by it. A field changes that with a :class:`Rule` in its metadata,
``field(metadata=rule(...))``; the value goes through these steps in this order:

``convert``     a function of the value, first (an enum's value, tuples as lists, a summary of a nested object)
``falsy_none``  an empty value (``""``, ``()``, ``{}``, 0) written as None
``nonfinite``   what NaN and infinities are written as, e.g. None (also inside lists and dicts; default: as they are)
``digits``      floats (numpy's too) written as ``round(float(x), digits)``, ints kept (also inside lists and dicts)
``omit_none``   the entry left out when the value is None
``flatten``     a dict value's items written in the entry's place (an item replaces an earlier entry of its key)

and ``key`` names the entry when it is not the field's name; ``skip`` leaves the field out. :func:`lists` is the
``convert`` for tuples written as lists.

Values that are not fields (properties, or methods taking no argument) are listed by name with their rules in
the class's ``serial_computed`` and written after the fields; ``serial_order`` names every entry (fields and
computed) in the dict's order when that is not the fields' order followed by the computed ones.
"""

from __future__ import annotations

import dataclasses
import math
import numbers
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any, ClassVar

META = "serial"  # the key of a field's metadata that holds its Rule
KEEP = object()  # Rule.nonfinite's default: NaN and infinities written as they are


@dataclasses.dataclass(frozen=True, slots=True)
class Rule:
    """How one entry is written; see the module docstring for the order of the steps."""

    key: str | None = None
    skip: bool = False
    convert: Callable[[Any], Any] | None = None
    falsy_none: bool = False
    nonfinite: Any = KEEP
    digits: int | None = None
    omit_none: bool = False
    flatten: bool = False


PLAIN = Rule()


def rule(*, key: str | None = None, skip: bool = False, convert: Callable[[Any], Any] | None = None,
         falsy_none: bool = False, nonfinite: Any = KEEP, digits: int | None = None, omit_none: bool = False,
         flatten: bool = False) -> dict[str, Rule]:
    """Field metadata carrying a :class:`Rule`: ``x: float = field(metadata=rule(digits=4))``."""
    return {META: Rule(key, skip, convert, falsy_none, nonfinite, digits, omit_none, flatten)}


def computed(**rules: Rule) -> Mapping[str, Rule]:
    """A class's ``serial_computed``: attribute name -> rule, in the order they are written."""
    return MappingProxyType(rules)


class Serial:
    """Base of a dataclass whose ``to_dict`` is derived from its fields (see the module docstring)."""

    __slots__ = ()
    serial_computed: ClassVar[Mapping[str, Rule]] = MappingProxyType({})
    serial_order: ClassVar[tuple[str, ...]] = ()

    def to_dict(self) -> dict[str, Any]:
        return to_dict(self)


def _entries(cls: type) -> list[tuple[str, Rule, bool]]:
    """(attribute, rule, is a field) of every entry of ``cls``, in the dict's order."""
    entries = [(f.name, f.metadata.get(META, PLAIN), True) for f in dataclasses.fields(cls)]
    entries += [(name, r, False) for name, r in getattr(cls, "serial_computed", {}).items()]
    entries = [e for e in entries if not e[1].skip]
    order: tuple[str, ...] = getattr(cls, "serial_order", ())
    if order:
        by_name = {e[0]: e for e in entries}
        if sorted(order) != sorted(by_name):
            raise TypeError(f"{cls.__name__}.serial_order {order} must name each written entry once: "
                            f"{sorted(by_name)}")
        entries = [by_name[name] for name in order]
    return entries


_ENTRIES: dict[type, list[tuple[str, Rule, bool]]] = {}


def to_dict(obj: Any) -> dict[str, Any]:
    """The dict of the dataclass instance ``obj`` by its fields' rules (and its class's computed entries)."""
    cls = type(obj)
    entries = _ENTRIES.get(cls)
    if entries is None:
        entries = _ENTRIES[cls] = _entries(cls)
    out: dict[str, Any] = {}
    for name, r, is_field in entries:
        value = getattr(obj, name)
        if not is_field and callable(value):
            value = value()
        value = _written(value, r)
        if r.omit_none and value is None:
            continue
        if r.flatten:
            out.update(value)
        else:
            out[r.key or name] = value
    return out


def _written(value: Any, r: Rule) -> Any:
    """``value`` as an entry with rule ``r`` writes it (the steps before ``omit_none``)."""
    if r.convert is not None:
        value = r.convert(value)
    value = plain(value)
    if r.falsy_none and not value:
        return None
    if r.nonfinite is not KEEP or r.digits is not None:
        value = _numbers(value, r.nonfinite, r.digits)
    return value


def plain(value: Any) -> Any:
    """Nested dataclasses as dicts (by their own ``to_dict`` where they have one), containers copied."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        own = getattr(value, "to_dict", None)
        return own() if callable(own) else to_dict(value)
    if isinstance(value, list | tuple):
        items = [plain(v) for v in value]
        return type(value)(*items) if hasattr(value, "_fields") else type(value)(items)
    if isinstance(value, dict):
        return type(value)((plain(k), plain(v)) for k, v in value.items())
    return value


def lists(value: Any) -> Any:
    """``value`` with its tuples as lists, nested ones too (a ``convert`` for tuple fields)."""
    if isinstance(value, list | tuple):
        return [lists(v) for v in value]
    return value


def _numbers(value: Any, nonfinite: Any, digits: int | None) -> Any:
    if isinstance(value, list | tuple) and not hasattr(value, "_fields"):
        return type(value)(_numbers(v, nonfinite, digits) for v in value)
    if isinstance(value, dict):
        return type(value)((k, _numbers(v, nonfinite, digits)) for k, v in value.items())
    if not _is_float(value):
        return value  # ints and bools as they are
    if nonfinite is not KEEP and not math.isfinite(value):
        return nonfinite
    return value if digits is None else round(float(value), digits)


def _is_float(value: Any) -> bool:
    """A Python or numpy float (not an int, a bool or a numpy integer)."""
    if isinstance(value, float):
        return True
    if value is None or isinstance(value, int | str):
        return False
    return isinstance(value, numbers.Real) and not isinstance(value, numbers.Integral)
