"""``housing_mount``: drive-unit housing roll on its rubber mounts.

The resolver reads rotor speed relative to the stator, so housing roll shows directly in the
measured speed (rotor minus housing), mostly at the mount mode (12-25 Hz) excited by impacts.
The effect rescales the mount stiffness and damping of the model's housing (on the classic layout,
switching the housing on with the model's values when the diagnosed vehicle has it fixed). A stage
chain without a housing on mounts (no ``[housing]``, e.g. a chain drive bolted to the chassis) has
nothing to rescale: the effect reports that it does not apply. Parameters are base-2
logarithms of the scale factors: priors from a quarter to four times the nominal mount.
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values


def _applies(vehicle: Any) -> str:
    if not vehicle.housing_described:
        return "the vehicle has no drive-unit housing on mounts (no [housing] in its stage chain)"
    return ""


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    if _applies(vehicle):  # nothing to rescale (callers that ask first skip the effect)
        return {}
    h = vehicle.housing
    return {
        "housing.enabled": True,
        "housing.mount_stiffness": h.mount_stiffness * 2.0 ** v["stiffness_log2"],
        "housing.mount_damping": h.mount_damping * 2.0 ** v["damping_log2"],
    }


EFFECT = Effect(
    id="housing_mount",
    title="Drive-unit housing roll on its mounts",
    params=(
        ParamSpec("stiffness_log2", "log2(x nominal)", -2.0, 2.0, 0.0, "mount roll stiffness scale, base-2 log"),
        ParamSpec("damping_log2", "log2(x nominal)", -2.0, 2.0, 0.0, "mount roll damping scale, base-2 log"),
    ),
    vehicle_change=_changes,
    model="multibody",
    applies=_applies,
    order=20,
)
