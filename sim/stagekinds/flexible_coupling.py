"""``flexible_coupling``: an elastomer (rubber) shaft coupling, coaxial, with no lash.

A rubber disc, jaw or doughnut coupling between two shafts: a spring and a damper in parallel
(elastomers damp far more than steel: damping ratios of 0.05-0.2 at the shuffle), optionally
hardening (``cubic_stiffness``), and no clearance, so it carries no gap: what-ifs, tolerance
bands and gap events do not name it. Its stiffness, damping and tolerance bands are read and
varied like any stage's (``stage.<name>.stiffness``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sim.stagekinds.base import KindDoc, StageKind

if TYPE_CHECKING:
    from sim.stages import Stage


class FlexibleCoupling(StageKind):
    name = "flexible_coupling"
    order = 15
    optional = ("cubic_stiffness",)
    reference_stage = "spline"
    doc = KindDoc("elastomer (rubber) coupling, coaxial, no lash: no gap", "1", "kept", "none")

    def has_gap(self, s: Stage) -> bool:
        return False


KIND = FlexibleCoupling()
