"""What an unmodelled effect is: a small, bounded, parametric extension of the driveline model.

An :class:`Effect` has at most three parameters (:class:`ParamSpec`, each with physical bounds and
an ``off`` value at which the effect vanishes) and acts in up to three places:

``vehicle``
    parameter changes through the model's own fields: a dict of dotted fields for
    ``Vehicle.with_changes``, e.g. lash sizes (several effects merge into one call);
``input``
    a transform of the torque input before it reaches the model, e.g. an actuator lag;
``output``
    a transform of the simulated motor speed before it is compared, e.g. sensor filtering.

Input and output transforms work on the diagnosis' uniform 1 ms grid, so that sub-sample delays
and lags are represented; the caller feeds the transformed input to the simulator with linear
interpolation. The current library needs none: the simulator carries torque lag, sensor filtering
and drag as its own optional fields, which keeps a fitted effect storable in a vehicle file.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sim.errors import ParameterError

FloatArray = npt.NDArray[np.float64]
Values = Mapping[str, float]
VehicleChange = Callable[[Any, Values], dict[str, Any]]
Applicability = Callable[[Any], str]  # vehicle -> "" when the effect applies, else the reason it does not
InputTransform = Callable[[FloatArray, FloatArray, Values], FloatArray]
OutputTransform = Callable[[FloatArray, FloatArray, Values], FloatArray]


@dataclass(frozen=True)
class ParamSpec:
    """One effect parameter.

    Attributes
    ----------
    name : identifier, unique within the effect.
    unit : SI unit of the value.
    lo, hi : physical prior bounds (inclusive).
    off : value at which the effect vanishes (inside ``[lo, hi]``).
    doc : one line saying what it is.
    """

    name: str
    unit: str
    lo: float
    hi: float
    off: float
    doc: str = ""

    def __post_init__(self) -> None:
        if not self.lo < self.hi:
            raise ParameterError(self.name, (self.lo, self.hi), "prior bounds must satisfy lo < hi")
        if not self.lo <= self.off <= self.hi:
            raise ParameterError(self.name, self.off, f"'off' value must lie in [{self.lo}, {self.hi}]")

    def check(self, value: float) -> float:
        v = float(value)
        if not np.isfinite(v) or v < self.lo - 1e-12 or v > self.hi + 1e-12:
            raise ParameterError(self.name, value, f"outside its prior range [{self.lo}, {self.hi}] {self.unit}")
        return min(max(v, self.lo), self.hi)


@dataclass(frozen=True)
class Effect:
    """A candidate effect.

    Attributes
    ----------
    id : stable identifier used in reports (``torque_lag``, ``speed_sensor``...).
    title : human-readable name.
    params : parameter specs (at most three).
    vehicle_change : ``f(vehicle, values) -> {dotted field: value}`` or None.
    input_transform : ``f(t_fine, torque_fine, values) -> torque_fine`` or None.
    output_transform : ``f(t_fine, speed_fine, values) -> speed_fine`` or None.
    model : simulator model the effect needs (``"multibody"`` or ``"any"``).
    applies : ``f(vehicle) -> reason`` ("" when the effect exists on that vehicle), or None (always).
        An effect that does not apply changes nothing (:meth:`apply` returns the vehicle as it is),
        so a fit over it finds nothing; callers should skip it and show the reason.
    order : its place among the candidates (reports, the order of the fits): the registry
        (:mod:`sim.effects`) sorts by ``(order, id)``.
    """

    id: str
    title: str
    params: tuple[ParamSpec, ...]
    vehicle_change: VehicleChange | None = None
    input_transform: InputTransform | None = None
    output_transform: OutputTransform | None = None
    model: str = "any"
    notes: str = ""
    applies: Applicability | None = None
    order: int = 1000
    _names: tuple[str, ...] = field(init=False, repr=False, default=())

    def __post_init__(self) -> None:
        if len(self.params) > 3:
            raise ParameterError(self.id, len(self.params), "an effect has at most three parameters")
        object.__setattr__(self, "_names", tuple(p.name for p in self.params))

    @property
    def names(self) -> tuple[str, ...]:
        return self._names

    def off_values(self) -> dict[str, float]:
        return {p.name: p.off for p in self.params}

    def values(self, x: Sequence[float] | Values) -> dict[str, float]:
        """Checked parameter values from a sequence in ``params`` order or a mapping by name."""
        if isinstance(x, Mapping):
            unknown = set(x) - set(self.names)
            if unknown:
                raise ParameterError(self.id, sorted(unknown), f"unknown parameters; known: {list(self.names)}")
            return {p.name: p.check(x.get(p.name, p.off)) for p in self.params}
        seq = list(x)
        if len(seq) != len(self.params):
            raise ParameterError(self.id, seq, f"expects {len(self.params)} values {list(self.names)}")
        return {p.name: p.check(v) for p, v in zip(self.params, seq, strict=True)}

    def inapplicable(self, vehicle: Any) -> str:
        """Why this effect does not exist on ``vehicle`` (e.g. no housing on mounts), or "" if it does."""
        return self.applies(vehicle) if self.applies is not None else ""

    def apply(self, vehicle: Any, values: Values) -> Any:
        """``vehicle`` with this effect's field changes (unchanged for input/output-only effects and
        for an effect that does not apply to it, see :meth:`inapplicable`)."""
        if self.vehicle_change is None or self.inapplicable(vehicle):
            return vehicle
        return vehicle.with_changes(self.vehicle_change(vehicle, values))

    def describe(self, vehicle: Any = None) -> dict[str, Any]:
        """Plain description; with ``vehicle`` also ``not_applicable``: why it does not apply ("" if it does)."""
        out = {
            "id": self.id,
            "title": self.title,
            "model": self.model,
            "acts_on": [k for k, f in (("vehicle", self.vehicle_change), ("input", self.input_transform),
                                       ("output", self.output_transform)) if f is not None],
            "params": [{"name": p.name, "unit": p.unit, "lo": p.lo, "hi": p.hi, "off": p.off, "doc": p.doc}
                       for p in self.params],
            "notes": self.notes,
        }
        if vehicle is not None:
            out["not_applicable"] = self.inapplicable(vehicle)
        return out
