"""``planetary``: sun in, carrier out, ring fixed in the housing (ratio ``1 + ring/sun`` > 1, no reversal)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sim.errors import ParameterError
from sim.stagekinds.base import KindDoc, StageKind


class Planetary(StageKind):
    name = "planetary"
    order = 30
    geared = True
    optional = ("ratio", "teeth", "lash_rad", "cubic_stiffness", "referred_to")
    reference_stage = "mesh2"
    doc = KindDoc("sun in, carrier out, ring fixed in the housing",
                  "`ratio` (> 1) or `teeth = [sun, ring]` (r = 1 + ring/sun)", "kept", "`s (1 - r)`")

    def ratio_from_teeth(self, teeth: tuple[int, int]) -> float:
        return 1.0 + teeth[1] / teeth[0]

    def prepare(self, raw: Mapping[str, Any], data: dict[str, Any], label: str) -> None:
        super().prepare(raw, data, label)
        if data["ratio"] <= 1.0:
            raise ParameterError(f"{label}ratio", data["ratio"],
                                 "a planetary stage (sun in, carrier out, ring fixed) has ratio > 1")

    def housing_reaction(self, sense: float, r: float) -> float:
        return sense * (1.0 - r)


KIND = Planetary()
