"""What-if runs: scale or remove gaps, scale the torque, shape the torque near its zero crossing.

A :class:`WhatIf` is applied by :func:`sim.simulate` (``what_if=``) to the vehicle and the
torque input before the run, so a what-if result is an ordinary :class:`~sim.SimResult`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from sim.budget import MAX_OUTPUT_BYTES
from sim.errors import InputSignalError, ParameterError
from sim.params import Vehicle

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class WhatIf:
    """Changes for one what-if run.

    Attributes
    ----------
    gap_scale : gap name -> factor on its nominal size (0 removes it); ``"all"`` scales all of them;
        names are checked against the vehicle when applied (a stage chain names its gaps after its stages)
    torque_scale : factor on the whole torque input
    antijerk_rate : N m/s, rate limit on the torque while ``|T| < antijerk_band`` (0 = off)
    antijerk_band : N m, half-width of the band around zero torque where the limit applies
    changes : any other dotted vehicle field changes (``{"housing.enabled": False}``)
    """

    gap_scale: Mapping[str, float] = field(default_factory=dict)
    torque_scale: float = 1.0
    antijerk_rate: float = 0.0
    antijerk_band: float = 20.0
    changes: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name, s in self.gap_scale.items():
            if not np.isfinite(s) or s < 0:
                raise ParameterError(f"what_if.gap_scale.{name}", s, "must be a finite factor >= 0")
        if not np.isfinite(self.torque_scale):
            raise ParameterError("what_if.torque_scale", self.torque_scale, "must be finite")
        if not np.isfinite(self.antijerk_rate) or self.antijerk_rate < 0:
            raise ParameterError("what_if.antijerk_rate", self.antijerk_rate, "must be a finite rate >= 0 N m/s")
        if not np.isfinite(self.antijerk_band) or self.antijerk_band < 0:
            raise ParameterError("what_if.antijerk_band", self.antijerk_band, "must be a finite band >= 0 N m")

    def apply_vehicle(self, v: Vehicle) -> Vehicle:
        """``v`` with the gap scales and field changes; gap names are the vehicle's (stage names on a chain)."""
        changes: dict[str, object] = dict(self.changes)
        for name, s in self.gap_scale.items():
            if name != "all" and name not in v.gap_names:
                raise ParameterError(f"what_if.gap_scale.{name}", s,
                                     f"unknown gap; known: {list(v.gap_names)} or 'all'")
        for name in v.gap_names:
            s = self.gap_scale.get(name, 1.0) * self.gap_scale.get("all", 1.0)
            if s != 1.0:
                changes[f"gaps.{name}"] = v.gap(name).nominal * s
        return v.with_changes(changes)

    def apply_torque(self, t: F64, torque: F64) -> tuple[F64, F64, bool]:
        """Scaled and (if asked) rate-limited torque. Returns ``(t, torque, resampled)``.

        The rate limit needs a time base, so shaped torque is returned on a 1 ms grid (to be
        interpolated linearly); unshaped torque keeps the original samples.
        """
        q = torque * self.torque_scale
        if self.antijerk_rate <= 0:
            return t, q, False
        step = 1e-3
        n = int((t[-1] - t[0]) / step) + 1
        if n * 24 > MAX_OUTPUT_BYTES:  # grid, interpolated and shaped torque
            raise InputSignalError(f"anti-jerk shaping resamples the torque at {step:g} s: {float(t[-1] - t[0]):.6g} s "
                                   f"of input would need {n:.4g} samples, over the output budget of "
                                   f"{MAX_OUTPUT_BYTES / 2**20:.0f} MiB")
        grid = np.arange(t[0], t[-1] + 0.5 * step, step)
        x = np.interp(grid, t, q)
        return grid, antijerk(grid, x, self.antijerk_rate, self.antijerk_band), True


def antijerk(t: F64, torque: F64, rate: float, band: float, catchup: float = 5.0) -> F64:
    """Anti-jerk shaping: limit ``|dT/dt|`` to ``rate`` (N m/s) while the torque is near zero.

    The limit applies while the shaped torque is within ``band`` (N m) of zero or the request
    lies on the other side of zero (a crossing). Outside the band the output returns to the
    request at ``catchup * rate`` rather than jumping, so shaping never adds a step.
    Uniform grid ``t`` (s), torque (N m), both (n,).
    """
    y = np.empty_like(torque)
    y[0] = torque[0]
    step = float(t[1] - t[0]) if t.size > 1 else 0.0
    for k in range(1, torque.size):
        prev = y[k - 1]
        want = torque[k] - prev
        crossing = abs(prev) < band or (prev > 0) != (torque[k] > 0)
        dmax = rate * step * (1.0 if crossing else catchup)
        y[k] = prev + min(max(want, -dmax), dmax)
    return y


WHAT_IF_KEYS = ("gap", "torque", "anti_jerk", "anti_jerk_band", "set")


def parse_what_if(specs: Sequence[str]) -> WhatIf:
    """A :class:`WhatIf` from text items ``key=value`` (comma-separated, several strings allowed).

    Keys: ``gap=NAME:FACTOR`` (NAME a gap or ``all``; factor 0 removes it; repeatable),
    ``torque=FACTOR``, ``anti_jerk=RATE`` (N m/s near zero torque), ``anti_jerk_band=N_M``,
    ``set=dotted.field:VALUE`` (any vehicle field, a number or true/false; repeatable).
    Example: ``"gap=halfshaft:0.5,torque=0.8,anti_jerk=2000"``.

    Raises
    ------
    ParameterError : naming ``what_if.<key>`` and the offending text
    """
    gap_scale: dict[str, float] = {}
    changes: dict[str, object] = {}
    kw: dict[str, float] = {}
    for spec in specs:
        for item in (s.strip() for s in spec.split(",")):
            if not item:
                continue
            key, sep, value = item.partition("=")
            key = key.strip()
            if not sep or key not in WHAT_IF_KEYS:
                raise ParameterError("what_if", item, f"expected key=value with key one of {WHAT_IF_KEYS}")
            if key in ("gap", "set"):
                name, sep2, amount = value.partition(":")
                if not sep2:
                    raise ParameterError(f"what_if.{key}", value, f"expected {key}=NAME:VALUE")
                if key == "gap":
                    gap_scale[name.strip()] = _number(f"what_if.gap.{name.strip()}", amount)
                else:
                    changes[name.strip()] = _setting(f"what_if.set.{name.strip()}", amount)
            else:
                kw[key] = _number(f"what_if.{key}", value)
    return WhatIf(gap_scale=gap_scale, torque_scale=kw.get("torque", 1.0), antijerk_rate=kw.get("anti_jerk", 0.0),
                  antijerk_band=kw.get("anti_jerk_band", 20.0), changes=changes)


def _number(field_name: str, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ParameterError(field_name, text, "must be a number") from None


def _setting(field_name: str, text: str) -> object:
    low = text.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    value = _number(field_name, text)
    return int(value) if value.is_integer() and "." not in text and "e" not in low else value
