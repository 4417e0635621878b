"""app.serial: a dataclass's dict from its fields' rules."""

from __future__ import annotations

import enum
import json
import math
from dataclasses import asdict, dataclass, field
from operator import attrgetter
from typing import Any

import numpy as np
import pytest

from app.serial import PLAIN, Rule, Serial, computed, lists, rule, to_dict


class Colour(enum.Enum):
    RED = "red"


@dataclass(frozen=True)
class Inner:
    a: float
    b: tuple[int, ...] = (1, 2)


@dataclass(frozen=True)
class Own:
    x: int

    def to_dict(self) -> dict[str, Any]:
        return {"own": self.x}


@dataclass(frozen=True)
class Plain(Serial):
    n: int
    inner: Inner
    own: Own
    items: list[Inner]
    table: dict[str, tuple[float, ...]]


def test_without_rules_it_is_asdict_but_a_nested_to_dict_is_used() -> None:
    p = Plain(3, Inner(0.5), Own(7), [Inner(1.5, ())], {"k": (1.0, 2.0)})
    assert p.to_dict() == {"n": 3, "inner": {"a": 0.5, "b": (1, 2)}, "own": {"own": 7},
                           "items": [{"a": 1.5, "b": ()}], "table": {"k": (1.0, 2.0)}}
    assert type(p.to_dict()["inner"]["b"]) is tuple  # tuples stay tuples, as dataclasses.asdict keeps them
    copy = p.to_dict()
    copy["items"].append(1)
    assert p.items == [Inner(1.5, ())]  # containers are copies


@dataclass(frozen=True)
class Ruled(Serial):
    kept: str
    renamed: int = field(default=1, metadata=rule(key="other"))
    hidden: float = field(default=0.0, metadata=rule(skip=True))
    colour: Colour = field(default=Colour.RED, metadata=rule(convert=attrgetter("value")))
    pairs: tuple[tuple[float, float], ...] = field(default=((1.0, 2.0),), metadata=rule(convert=lists))
    rounded: float = field(default=1.23456789, metadata=rule(digits=3))
    figures: dict[str, Any] = field(default_factory=lambda: {"a": [0.11111, math.inf], "n": 7, "t": True},
                                    metadata=rule(digits=2, nonfinite=None))
    empty: tuple[str, ...] = field(default=(), metadata=rule(convert=lists, falsy_none=True))
    maybe: int | None = field(default=None, metadata=rule(omit_none=True))
    merged: dict[str, int] = field(default_factory=lambda: {"kept": 9, "extra": 1}, metadata=rule(flatten=True))


def test_each_rule() -> None:
    d = Ruled("k").to_dict()
    # "kept" is replaced in place by the flattened dict; its key keeps its first position
    assert d == {"kept": 9, "other": 1, "colour": "red", "pairs": [[1.0, 2.0]], "rounded": 1.235,
                 "figures": {"a": [0.11, None], "n": 7, "t": True}, "empty": None, "extra": 1}
    assert list(d) == ["kept", "other", "colour", "pairs", "rounded", "figures", "empty", "extra"]
    assert Ruled("k", maybe=0).to_dict()["maybe"] == 0  # only None is left out
    assert Ruled("k", empty=("a",)).to_dict()["empty"] == ["a"]


def test_digits_round_floats_as_python_does_and_keep_ints() -> None:
    @dataclass(frozen=True)
    class R(Serial):
        x: Any = field(metadata=rule(digits=2))

    assert R(2.675).to_dict() == {"x": round(2.675, 2)}
    got = R(np.float64(2.675)).to_dict()["x"]
    assert type(got) is float and got == round(2.675, 2)  # numpy floats are written as Python floats
    assert type(R(3).to_dict()["x"]) is int and type(R(np.int64(3)).to_dict()["x"]) is np.int64
    assert R(True).to_dict() == {"x": True}
    assert math.isnan(R(math.nan).to_dict()["x"]) and R(-math.inf).to_dict() == {"x": -math.inf}
    assert R(None).to_dict() == {"x": None} and R("a").to_dict() == {"x": "a"}


def test_nonfinite_replacement_and_the_order_of_steps() -> None:
    @dataclass(frozen=True)
    class R(Serial):
        nan: float = field(default=math.nan, metadata=rule(nonfinite=math.nan, digits=1))
        inf_as_none_omitted: float = field(default=math.inf, metadata=rule(nonfinite=None, omit_none=True))
        converted_first: float = field(default=0.0, metadata=rule(convert=lambda v: v + 0.26, digits=1))
        zero_is_none: float = field(default=0.0, metadata=rule(falsy_none=True, digits=1))

    d = R(inf_as_none_omitted=math.inf).to_dict()
    assert list(d) == ["nan", "converted_first", "zero_is_none"]
    assert math.isnan(d["nan"]) and d["converted_first"] == 0.3 and d["zero_is_none"] is None
    assert R(nan=math.inf, inf_as_none_omitted=2.0).to_dict()["inf_as_none_omitted"] == 2.0
    assert math.isnan(R(nan=math.inf).to_dict()["nan"])


@dataclass(frozen=True)
class Computed(Serial):
    a: int
    b: int = field(default=2, metadata=rule(key="bee"))

    serial_computed = computed(total=Rule(key="sum"), half=Rule(digits=1), describe=PLAIN)

    @property
    def total(self) -> int:
        return self.a + self.b

    @property
    def half(self) -> float:
        return self.total / 3

    def describe(self) -> str:
        return f"{self.a}+{self.b}"


@dataclass(frozen=True)
class Ordered(Computed):
    serial_order = ("describe", "b", "total", "a", "half")


def test_computed_entries_follow_the_fields_or_the_given_order() -> None:
    assert list(Computed(1).to_dict().items()) == [("a", 1), ("bee", 2), ("sum", 3), ("half", 1.0),
                                                   ("describe", "1+2")]
    assert list(Ordered(1).to_dict()) == ["describe", "bee", "sum", "a", "half"]


def test_an_order_must_name_every_entry_once() -> None:
    @dataclass(frozen=True)
    class Short(Computed):
        serial_order = ("a", "b", "total", "half")

    with pytest.raises(TypeError, match="must name each written entry once"):
        Short(1).to_dict()


def test_slotted_dataclasses_and_plain_ones_without_the_base() -> None:
    @dataclass(frozen=True, slots=True)
    class Slotted(Serial):
        a: float = field(default=0.123, metadata=rule(digits=1))

    assert Slotted().to_dict() == {"a": 0.1}
    assert to_dict(Inner(1.0)) == asdict(Inner(1.0))


def test_the_dicts_are_json_ready_where_the_values_are() -> None:
    d = Ruled("k").to_dict()
    assert json.loads(json.dumps(d)) == d
