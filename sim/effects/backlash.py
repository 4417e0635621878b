"""``backlash``: actual lash sizes off the nominal (tolerance midpoint) values.

Two scale factors, because at CAN rates only two groups are told apart by the data: the gaps
upstream of the half-shafts ("reducer": spline, gear/chain/planetary stages and the differential,
slammed by the rotor side) and the half-shaft gaps (CV or tripod joints and splines, both shafts
when they differ, slammed by the wheel side). The groups follow the vehicle's stage chain
(:func:`gap_groups`); on the classic layout they are spline, mesh1, mesh2, differential | halfshaft
as they always were, so stored diagnoses keep their meaning. Total motor-side lash
is what the gap-open time mostly measures; where the gap sits shows in the impact shape.
Priors: 0.25x to 2x the nominal (production spread plus wear).
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values
from sim.stagekinds import SHAFTS

REDUCER_GAPS = ("spline", "mesh1", "mesh2", "differential")  # the classic layout's reducer group


def gap_groups(vehicle: Any) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(reducer group, half-shaft group) of gap names on ``vehicle``'s chain, in chain order."""
    shafts = tuple(g for s in vehicle.chain if s.spec.role == SHAFTS for g in s.gap_names())
    return tuple(g for g in vehicle.gap_names if g not in shafts), shafts


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    reducer, shafts = gap_groups(vehicle)
    changes: dict[str, Any] = {f"gaps.{g}": vehicle.gap(g).nominal * v["reducer_scale"] for g in reducer}
    changes.update({f"gaps.{g}": vehicle.gap(g).nominal * v["halfshaft_scale"] for g in shafts})
    return changes


EFFECT = Effect(
    id="backlash",
    title="Backlash sizes off nominal (reducer and half-shaft)",
    params=(
        ParamSpec("reducer_scale", "-", 0.25, 2.0, 1.0,
                  "gaps upstream of the half-shafts (spline, gear stages, differential) x nominal"),
        ParamSpec("halfshaft_scale", "-", 0.25, 2.0, 1.0, "half-shaft gaps x nominal"),
    ),
    vehicle_change=_changes,
    order=10,
)
