"""``chain`` (alias ``belt``): roller chain or toothed belt, sprockets in the housing, slack as lash.

No reversal; the housing takes ``e = s (1 - r)`` of the coupling torque, so a chain drive rolls
the housing the other way from a gear pair.
"""

from __future__ import annotations

from sim.stagekinds.base import KindDoc, StageKind


class Chain(StageKind):
    name = "chain"
    order = 40
    aliases = ("belt",)
    geared = True
    optional = ("ratio", "teeth", "lash_rad", "cubic_stiffness", "referred_to")
    reference_stage = "mesh2"
    doc = KindDoc("roller chain or toothed belt, sprockets in the housing", "`ratio` or `teeth = [drive, driven]`",
                  "kept", "`s (1 - r)`")

    def housing_reaction(self, sense: float, r: float) -> float:
        return sense * (1.0 - r)


KIND = Chain()
