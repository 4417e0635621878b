"""``halfshaft``: ``count`` 1 or 2 driven shafts of ``segments`` pieces each, the last stage before the wheels.

Equal shafts are lumped in parallel into one chain of segments ending on the wheels body (all
driven wheels plus the car, ``I_W = n I_w + M R^2``). With a ``[stage.right]`` table the right
shaft has its own values: each shaft then drives its own wheel body (one wheel plus half the
car), and the open differential before them (left in ``Wiring.pending``) becomes the 3-body
coupling whose deflection is ``theta_case - (theta_left + theta_right) / 2``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from sim.stagekinds.base import SHAFTS, KindDoc, StageKind, Wiring

if TYPE_CHECKING:
    from sim.stages import Stage


class Halfshaft(StageKind):
    name = "halfshaft"
    order = 60
    role = SHAFTS
    required = ("stiffness", "damping")
    optional = ("inertia", "lash_rad", "segments", "count", "cubic_stiffness", "right")
    reference_stage = "halfshaft"
    doc = KindDoc("`count` 1 or 2 shafts, `segments` 1..20 pieces each; optional `[stage.right]`", "1", "kept",
                  "none")

    def driven_wheels(self, s: Stage) -> int:
        return s.count

    def wire(self, w: Wiring, s: Stage, body_name: str, coupling_name: str) -> None:
        bld, diff = w.bld, w.pending.pop("differential", None)
        if diff is not None and s.right is not None:
            left = bld.body(f"{diff.name}_left", 0.5 * diff.inertia)
            wheel_j = w.wheel_inertia + 0.5 * w.vehicle_inertia
            first = len(bld.rows)
            w.wheel = bld.shaft(s.name, left, "wheel_left", wheel_j, 1, s.stiffness, s.damping, s.inertia,
                                s.lash_rad.nominal, s.cubic_stiffness, s.segments, s.name)
            rs = s.right
            right = bld.body(f"{diff.name}_right", 0.5 * diff.inertia)
            w.wheel2 = bld.shaft(f"{s.name}_right", right, "wheel_right", wheel_j, 1, rs.stiffness, rs.damping,
                                 rs.inertia, rs.lash_rad.nominal, rs.cubic_stiffness, s.segments, f"{s.name}_right")
            bld.gaps = {g: (j + 1 if j >= first else j) for g, j in bld.gaps.items()}
            bld.gaps[diff.name] = first
            bld.rows.insert(first, (diff.name, w.cur, left, right, 1.0, 0.0, diff.stiffness, diff.damping,
                                    diff.lash_rad.nominal / 2, 1.0, diff.cubic_stiffness))
            w.own = w.wheel_inertia
        else:
            wheel_j = w.own + w.vehicle_inertia  # I_W = I_w + M R^2 / 2 per wheel
            w.wheel = bld.shaft(s.name, w.cur, "wheels", wheel_j, w.driven_wheels, s.stiffness, s.damping,
                                s.inertia, s.lash_rad.nominal, s.cubic_stiffness, s.segments, s.name)


KIND = Halfshaft()
