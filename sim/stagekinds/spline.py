"""``spline`` (alias ``coupling``): shaft torsion through a spline or a coupling, coaxial, with lash."""

from __future__ import annotations

from sim.stagekinds.base import KindDoc, StageKind


class Spline(StageKind):
    name = "spline"
    order = 10
    aliases = ("coupling",)
    reference_stage = "spline"
    doc = KindDoc("shaft torsion, spline or coupling, coaxial", "1", "kept", "none")


KIND = Spline()
