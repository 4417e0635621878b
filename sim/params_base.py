"""Shared pieces of the vehicle description: physical limits of its fields and the gap (lash) type.

Kept apart from :mod:`sim.params` so that the stage chain (:mod:`sim.stages`) and the classic
layout use the same limits and the same :class:`Gap` without importing each other.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sim.errors import ParameterError
from sim.fields import NONNEG, POS, check
from sim.fields import num as _f

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


def move_band(gap: dict[str, Any], old: Gap) -> None:
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
