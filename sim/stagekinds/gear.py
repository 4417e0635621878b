"""``gear``: an external gear pair with its centres in the housing.

The output turns the other way, and the mesh rolls on the housing: the housing takes
``e = s (1 + r)`` of the coupling torque (``s`` the input's true turning sense, ``r`` the ratio).
"""

from __future__ import annotations

from sim.stagekinds.base import KindDoc, StageKind


class Gear(StageKind):
    name = "gear"
    order = 20
    geared = True
    reverses = True
    optional = ("ratio", "teeth", "lash_rad", "cubic_stiffness", "referred_to")
    reference_stage = "mesh2"
    doc = KindDoc("external gear pair, centres in the housing", "`ratio` or `teeth = [drive, driven]`",
                  "**reversed**", "`s (1 + r)`")

    def housing_reaction(self, sense: float, r: float) -> float:
        return sense * (1.0 + r)


KIND = Gear()
