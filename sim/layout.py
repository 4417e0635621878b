"""Classic layout <-> stage chain: the classic file read as five stages, and written as a chain.

A classic vehicle file (``[reducer]``, ``[halfshaft]``, ``[gaps.*]``: two external gear pairs, an
open differential, ``count`` equal half-shafts) is simulated through the same stage builder as a
``[[stage]]`` file; :data:`CLASSIC_STAGES` is the one translation (each stage's kind, name and the
classic fields that hold its values), from which :func:`legacy_stages` builds its stages (named
after its gaps, so gap names, what-ifs and effects stay as they were) and :data:`FIELD_MAP` maps
the classic dotted fields. :func:`stage_layout` writes any classic vehicle as an
equivalent stage file (the housing stated explicitly, cubic stiffnesses moved onto the stages,
tolerance paths renamed).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from sim.errors import ParameterError
from sim.params_base import RATIO
from sim.stagekinds import SHAFTS
from sim.stages import Stage, stage_dict

if TYPE_CHECKING:
    from sim.params import Vehicle

CLASSIC_GAPS = ("spline", "mesh1", "mesh2", "differential", "halfshaft")


@dataclass(frozen=True)
class ClassicStage:
    """One stage of the classic layout: where its values sit in the classic file, and its model names."""

    kind: str
    name: str  # also the name of its gap (``[gaps.<name>]``) and of its cubic term in ``progressive_stiffness``
    fields: Mapping[str, str]  # stage field -> classic dotted field
    ratio: str = ""  # the Reducer property giving the stage ratio (gear pairs)
    body_name: str = ""  # body and coupling names the classic model always gave (stored results keep them)
    coupling_name: str = ""


# the one translation of the classic layout: its five stages in chain order
CLASSIC_STAGES = (
    ClassicStage("spline", "spline", {"inertia": "reducer.input_shaft_inertia",
                                      "stiffness": "reducer.spline_stiffness", "damping": "reducer.spline_damping"},
                 body_name="input_shaft"),
    ClassicStage("gear", "mesh1", {"inertia": "reducer.intermediate_inertia", "stiffness": "reducer.mesh1_stiffness",
                                   "damping": "reducer.mesh1_damping"},
                 ratio="ratio1", body_name="intermediate", coupling_name="gear1"),
    ClassicStage("gear", "mesh2", {"inertia": "reducer.differential_inertia", "stiffness": "reducer.mesh2_stiffness",
                                   "damping": "reducer.mesh2_damping"},
                 ratio="ratio2", body_name="differential", coupling_name="gear2"),
    ClassicStage("differential", "differential", {"inertia": "reducer.side_gears_inertia",
                                                  "stiffness": "reducer.diff_stiffness",
                                                  "damping": "reducer.diff_damping"},
                 body_name="side_gears", coupling_name="diff"),
    ClassicStage("halfshaft", "halfshaft", {"stiffness": "halfshaft.stiffness", "damping": "halfshaft.damping",
                                            "inertia": "halfshaft.inertia", "segments": "halfshaft.segments",
                                            "count": "halfshaft.count"}),
)
# classic dotted fields -> the stage field that holds the same value (the numeric, banded ones)
FIELD_MAP = {classic: f"stage.{c.name}.{key}" for c in CLASSIC_STAGES for key, classic in c.fields.items()
             if key in ("inertia", "stiffness", "damping")}


def classic_field(stage: str, attr: str) -> str:
    """The classic file's dotted field holding ``attr`` of its stage ``stage`` (ParameterError where the classic
    layout has no such stage or field)."""
    for c in CLASSIC_STAGES:
        if c.name != stage:
            continue
        if attr in c.fields:
            return c.fields[attr]
        if attr == "cubic_stiffness":
            return f"effects.progressive_stiffness.{stage}"
        raise ParameterError(f"stage.{stage}.{attr}", attr, f"the classic layout's {stage} has no such field")
    raise ParameterError(f"stage.{stage}", stage, f"no such stage; known: {[c.name for c in CLASSIC_STAGES]}")


def legacy_stages(v: Vehicle) -> tuple[Stage, ...]:
    """The classic layout as stages: spline, mesh1, mesh2 (gear pairs), differential, halfshaft."""
    red, g, ps = v.reducer, v.gaps, v.effects.progressive_stiffness
    assert red is not None and g is not None
    return tuple(
        Stage(kind=c.kind, name=c.name, lash_rad=getattr(g, c.name), cubic_stiffness=getattr(ps, c.name),
              body_name=c.body_name, coupling_name=c.coupling_name,
              **({"ratio": getattr(red, c.ratio)} if c.ratio else {}),
              **{key: v.get(path) for key, path in c.fields.items()})
        for c in CLASSIC_STAGES)


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


