"""The Signal value object.

A :class:`Signal` is ``t`` (float64 seconds since the start of the measurement,
strictly increasing after construction via :meth:`Signal.from_samples`), ``values``
(float64, NaN where the source said "not available"), a unit and an interpolation
mode: ``PREVIOUS`` for discrete values (pedal switch, gear, enumerations), ``LINEAR``
for continuous physical quantities.
"""

from __future__ import annotations

import enum
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


class Interp(enum.Enum):
    PREVIOUS = "previous"
    LINEAR = "linear"


@dataclass(frozen=True)
class Signal:
    name: str
    t: FloatArray  # s since measurement start, shape (n,)
    values: FloatArray  # shape (n,)
    unit: str = ""
    interp: Interp = Interp.LINEAR
    labels: Mapping[int, str] = field(default_factory=dict)  # enumeration labels, values stay numeric

    def __post_init__(self) -> None:
        if self.t.shape != self.values.shape or self.t.ndim != 1:
            raise ValueError(
                f"signal {self.name}: t {self.t.shape} and values {self.values.shape} must be equal 1-D shapes"
            )

    @classmethod
    def from_samples(
        cls,
        name: str,
        t: npt.ArrayLike,
        values: npt.ArrayLike,
        unit: str = "",
        interp: Interp = Interp.LINEAR,
        labels: Mapping[int, str] | None = None,
    ) -> Signal:
        """Build a signal, sorting by time and keeping the last sample of duplicate times."""
        ta = np.asarray(t, dtype=np.float64)
        va = np.asarray(values, dtype=np.float64)
        if ta.shape != va.shape:
            raise ValueError(f"signal {name}: {ta.shape[0]} times but {va.shape[0]} values")
        if ta.size and np.any(np.diff(ta) <= 0):
            order = np.argsort(ta, kind="stable")
            ta, va = ta[order], va[order]
            keep = np.ones(ta.size, bool)
            keep[:-1] = ta[1:] != ta[:-1]
            ta, va = ta[keep], va[keep]
        return cls(name, ta, va, unit, interp, dict(labels or {}))

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if self.t.size > 1 else 0.0

    def at(self, t: npt.ArrayLike) -> FloatArray:
        """Values at times ``t`` using this signal's interpolation mode (NaN outside the span)."""
        tq = np.asarray(t, dtype=np.float64)
        if self.t.size == 0:
            return np.full(tq.shape, np.nan)
        if self.interp is Interp.LINEAR:
            out = np.interp(tq, self.t, self.values, left=np.nan, right=np.nan)
        else:
            idx = np.searchsorted(self.t, tq, side="right") - 1
            out = np.where(idx >= 0, self.values[np.clip(idx, 0, None)], np.nan)
            out = np.where(tq > self.t[-1], self.values[-1], out)  # hold last value
        return np.asarray(out, dtype=np.float64)

    def window(self, t0: float, t1: float) -> Signal:
        """Samples with ``t0 <= t <= t1``."""
        m = (self.t >= t0) & (self.t <= t1)
        return Signal(self.name, self.t[m], self.values[m], self.unit, self.interp, self.labels)

    def resample(self, t: npt.ArrayLike) -> Signal:
        tq = np.asarray(t, dtype=np.float64)
        return Signal(self.name, tq, self.at(tq), self.unit, self.interp, self.labels)


@dataclass
class SignalSet(Mapping[str, Signal]):
    """Canonical channels by name (``pedal_pct``, ``motor_torque_nm``, ``motor_speed_rpm``...)."""

    signals: dict[str, Signal] = field(default_factory=dict)

    def __getitem__(self, key: str) -> Signal:
        return self.signals[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.signals)

    def __len__(self) -> int:
        return len(self.signals)

    def add(self, signal: Signal) -> None:
        self.signals[signal.name] = signal

    def span(self) -> tuple[float, float]:
        """Earliest and latest sample time over all signals."""
        starts = [s.t[0] for s in self.signals.values() if len(s)]
        ends = [s.t[-1] for s in self.signals.values() if len(s)]
        if not starts:
            return (0.0, 0.0)
        return (float(min(starts)), float(max(ends)))
