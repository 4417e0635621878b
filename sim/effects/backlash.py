"""``backlash``: actual lash sizes off the nominal (tolerance midpoint) values.

Two scale factors, because at CAN rates only two groups are told apart by the data: the gaps in
the reducer (spline, both meshes, differential: inside the drive unit, slammed by the rotor side)
and the half-shaft gap (CV joints and splines, slammed by the wheel side). Total motor-side lash
is what the gap-open time mostly measures; where the gap sits shows in the impact shape.
Priors: 0.25x to 2x the nominal (production spread plus wear).
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values

REDUCER_GAPS = ("spline", "mesh1", "mesh2", "differential")


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    changes: dict[str, Any] = {f"gaps.{g}": getattr(vehicle.gaps, g).nominal * v["reducer_scale"] for g in REDUCER_GAPS}
    changes["gaps.halfshaft"] = vehicle.gaps.halfshaft.nominal * v["halfshaft_scale"]
    return changes


EFFECT = Effect(
    id="backlash",
    title="Backlash sizes off nominal (reducer and half-shaft)",
    params=(
        ParamSpec("reducer_scale", "-", 0.25, 2.0, 1.0, "reducer gaps (spline, meshes, differential) x nominal"),
        ParamSpec("halfshaft_scale", "-", 0.25, 2.0, 1.0, "half-shaft gap x nominal"),
    ),
    vehicle_change=_changes,
)
