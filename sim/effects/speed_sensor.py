"""``speed_sensor``: the inverter's speed signal is filtered and delayed.

The resolver angle becomes a speed in the inverter, usually through a low-pass filter, and is
reported with a delay::

    n_reported(t) = F[n_rotor - n_housing](t - delay),   F: tau n' = n_in - n

Applied through the simulator's own ``effects.speed_sensor`` fields (its sample-and-hold and
resolution stay as the vehicle file says: they are steps in the parameter, which a least-squares
fit cannot follow). On a linear driveline an output filter and an input lag are the same operator;
only the nonlinear gap and impact phases separate this effect from ``torque_lag``.
Priors: filter time constants of 0-30 ms, delays of 0-10 ms.
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    return {"effects.speed_sensor.tau_s": v["tau_s"],
                                 "effects.speed_sensor.delay_s": v["delay_s"]}


EFFECT = Effect(
    id="speed_sensor",
    title="Speed-signal filtering and delay in the inverter",
    params=(
        ParamSpec("tau_s", "s", 0.0, 0.030, 0.0, "first-order filter time constant"),
        ParamSpec("delay_s", "s", 0.0, 0.010, 0.0, "reporting delay"),
    ),
    vehicle_change=_changes,
    order=40,
)
