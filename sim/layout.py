"""Classic layout <-> stage chain: the classic file read as five stages, and written as a chain.

A classic vehicle file (``[reducer]``, ``[halfshaft]``, ``[gaps.*]``: two external gear pairs, an
open differential, ``count`` equal half-shafts) is simulated through the same stage builder as a
``[[stage]]`` file; :func:`legacy_stages` gives its stages (named after its gaps, so gap names,
what-ifs and effects stay as they were). :func:`stage_layout` writes any classic vehicle as an
equivalent stage file (the housing stated explicitly, cubic stiffnesses moved onto the stages,
tolerance paths renamed).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from sim.errors import ParameterError
from sim.params_base import RATIO
from sim.stagekinds import SHAFTS
from sim.stages import Stage, stage_dict

if TYPE_CHECKING:
    from sim.params import Vehicle

CLASSIC_GAPS = ("spline", "mesh1", "mesh2", "differential", "halfshaft")
# classic dotted fields -> the stage field that holds the same value
FIELD_MAP = {
    "reducer.input_shaft_inertia": "stage.spline.inertia", "reducer.spline_stiffness": "stage.spline.stiffness",
    "reducer.spline_damping": "stage.spline.damping", "reducer.intermediate_inertia": "stage.mesh1.inertia",
    "reducer.mesh1_stiffness": "stage.mesh1.stiffness", "reducer.mesh1_damping": "stage.mesh1.damping",
    "reducer.differential_inertia": "stage.mesh2.inertia", "reducer.mesh2_stiffness": "stage.mesh2.stiffness",
    "reducer.mesh2_damping": "stage.mesh2.damping", "reducer.side_gears_inertia": "stage.differential.inertia",
    "reducer.diff_stiffness": "stage.differential.stiffness", "reducer.diff_damping": "stage.differential.damping",
    "halfshaft.stiffness": "stage.halfshaft.stiffness", "halfshaft.damping": "stage.halfshaft.damping",
    "halfshaft.inertia": "stage.halfshaft.inertia",
}


def legacy_stages(v: Vehicle) -> tuple[Stage, ...]:
    """The classic layout as stages: spline, mesh1, mesh2 (gear pairs), differential, halfshaft."""
    red, hs, g, ps = v.reducer, v.halfshaft, v.gaps, v.effects.progressive_stiffness
    assert red is not None and hs is not None and g is not None
    return (  # body and coupling names as the classic model always gave them (stored results keep them)
        Stage(kind="spline", name="spline", stiffness=red.spline_stiffness, damping=red.spline_damping,
              inertia=red.input_shaft_inertia, lash_rad=g.spline, cubic_stiffness=ps.spline,
              body_name="input_shaft"),
        Stage(kind="gear", name="mesh1", ratio=red.ratio1, stiffness=red.mesh1_stiffness, damping=red.mesh1_damping,
              inertia=red.intermediate_inertia, lash_rad=g.mesh1, cubic_stiffness=ps.mesh1,
              body_name="intermediate", coupling_name="gear1"),
        Stage(kind="gear", name="mesh2", ratio=red.ratio2, stiffness=red.mesh2_stiffness, damping=red.mesh2_damping,
              inertia=red.differential_inertia, lash_rad=g.mesh2, cubic_stiffness=ps.mesh2,
              body_name="differential", coupling_name="gear2"),
        Stage(kind="differential", name="differential", stiffness=red.diff_stiffness, damping=red.diff_damping,
              inertia=red.side_gears_inertia, lash_rad=g.differential, cubic_stiffness=ps.differential,
              body_name="side_gears", coupling_name="diff"),
        Stage(kind="halfshaft", name="halfshaft", stiffness=hs.stiffness, damping=hs.damping, inertia=hs.inertia,
              segments=hs.segments, count=hs.count, lash_rad=g.halfshaft, cubic_stiffness=ps.halfshaft),
    )


def stage_layout(v: Vehicle) -> dict[str, Any]:
    """A classic vehicle as the dict of an equivalent ``[[stage]]`` file (same simulation results)."""
    data = v.to_dict()
    for key in ("reducer", "halfshaft", "gaps"):
        data.pop(key, None)
    data["stage"] = [stage_dict(s) for s in legacy_stages(v)]
    ps = data.get("effects", {}).get("progressive_stiffness", {})
    for g in CLASSIC_GAPS:
        ps.pop(g, None)
    tolerances = {}
    for path, band in data.get("tolerances", {}).items():
        if path.startswith(("reducer.", "halfshaft.")) and path not in FIELD_MAP:
            raise ParameterError(f"tolerances.{path}", band, "has no stage equivalent")
        tolerances[FIELD_MAP.get(path, path)] = band
    data["tolerances"] = tolerances
    return data


def shaft_gap(v: Vehicle) -> str:
    """The gap sensitivities are normalised to and the free rotor side ends at: the (left) half-shaft
    gap, or the last gap of a chain without half-shafts."""
    for s in v.chain:
        if s.spec.role == SHAFTS:
            return s.name
    return v.gap_names[-1]


def stage_checks(v: Vehicle) -> None:
    """Whole-vehicle checks of a stage chain: total ratio, and effects that name classic gaps."""
    if not RATIO[0] <= v.ratio <= RATIO[1]:
        raise ParameterError("stage", f"total ratio {v.ratio:.4g}",
                             f"outside the physical range [{RATIO[0]:g}, {RATIO[1]:g}] (product of the stage ratios)")
    ps = v.effects.progressive_stiffness
    for g in CLASSIC_GAPS:
        if getattr(ps, g) != 0.0:
            raise ParameterError(f"effects.progressive_stiffness.{g}", getattr(ps, g),
                                 "names a classic-layout gap; a stage chain gives cubic_stiffness on each stage")
    last = v.stages[-1]
    if last.right is not None and v.effects.tyre_slip.enabled:
        raise ParameterError("effects.tyre_slip.enabled", True,
                             f"not available with unequal half-shafts (stage '{last.name}' has a right shaft)")


