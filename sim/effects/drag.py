"""``drag``: friction and drag losses on the rotor side (Coulomb plus speed-proportional).

Bearing, seal and oil-churning losses act on the motor side of every backlash::

    T_loss = T_c tanh(omega / 1 rad/s) + b omega

Applied through the simulator's ``effects.drag`` fields. On a log whose motor speed never changes
sign the Coulomb part looks like a road-load change (a nuisance parameter, acting on the wheel
side); it separates only in the gap phases, where the motor runs free of the road. The viscous
part is told apart by events at different speeds. Priors: 0-6 N m Coulomb, 0-0.02 N m s/rad
(about 10 N m at 5000 rpm).
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    return {"effects.drag.coulomb_nm": v["coulomb_nm"],
                                 "effects.drag.viscous_nms": v["viscous_nms"]}


EFFECT = Effect(
    id="drag",
    title="Friction and drag losses (Coulomb plus viscous)",
    params=(
        ParamSpec("coulomb_nm", "N m", 0.0, 6.0, 0.0, "Coulomb friction torque at the rotor"),
        ParamSpec("viscous_nms", "N m s/rad", 0.0, 0.02, 0.0, "viscous drag coefficient at the rotor"),
    ),
    vehicle_change=_changes,
    order=50,
)
