"""``progressive_stiffness``: hardening half-shaft and mount springs.

Rubber-bushed mounts and, to a lesser degree, shafts with splines stiffen as they deflect. The
simulator adds a cubic term ``k3 x^3`` to a coupling's spring ``k x``
(``effects.progressive_stiffness.<coupling>``). The parameters here are the *relative stiffness
increase at a reference deflection* (more readable than ``k3`` in N m/rad^3)::

    k3 = rel * k / x_ref^2      (the tangent stiffness is k (1 + 3 rel) at x = x_ref)

with ``x_ref = 0.1 rad`` for a half-shaft (its wind-up under full drive torque) and
``x_ref = 0.02 rad`` for the housing roll mount. Priors: 0 to 4 for a half-shaft (no hardening to
13 times the tangent stiffness at 0.1 rad: splines coming into full engagement) and 0 to 20 for the
mount (a rubber mount running onto its snubber stiffens by an order of magnitude). The mount's range
was 0 to 2 until the independent generator's hardening mount (docs/diagnosis.md) drove every fit to
that bound, where a linear mount change then took up the rest as a second, false effect.
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values
from sim.stagekinds import SHAFTS

HALFSHAFT_REF_RAD = 0.1
MOUNT_REF_RAD = 0.02


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    # the mount's term wherever the file describes a housing (a classic layout always does)
    out: dict[str, Any] = ({"effects.progressive_stiffness.mount": v["mount_rel"] * vehicle.housing.mount_stiffness
                            / MOUNT_REF_RAD**2} if vehicle.housing_described else {})
    for s in vehicle.chain:  # the cubic term of each half-shaft (both when unequal)
        if s.spec.role == SHAFTS:
            out[vehicle.field_of(s.name, "cubic_stiffness")] = v["halfshaft_rel"] * s.stiffness / HALFSHAFT_REF_RAD**2
            if s.right is not None:
                out[vehicle.field_of(s.name, "right.cubic_stiffness")] = (v["halfshaft_rel"] * s.right.stiffness
                                                                          / HALFSHAFT_REF_RAD**2)
    return out


EFFECT = Effect(
    id="progressive_stiffness",
    title="Progressive (hardening) half-shaft and mount stiffness",
    params=(
        ParamSpec("halfshaft_rel", "-", 0.0, 4.0, 0.0, "half-shaft k3 as relative hardening at 0.1 rad"),
        ParamSpec("mount_rel", "-", 0.0, 20.0, 0.0, "mount roll k3 as relative hardening at 0.02 rad"),
    ),
    vehicle_change=_changes,
    model="multibody",
    order=60,
)
