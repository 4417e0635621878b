"""``torque_lag``: the air-gap torque lags the torque reported on CAN.

The inverter's current loop and torque estimator make the torque acting on the rotor a delayed,
first-order-lagged copy of the reported value::

    T_airgap(t) = L[T_can](t - delay),   L: tau T' = T_in - T

Applied through the simulator's own ``effects.torque_lag`` fields. A pure delay is
indistinguishable from the torque-speed time offset the diagnosis always fits (bounded to a few
CAN periods); only a delay beyond that bound and the lag's low-pass shape are attributable.
Priors: current-loop/estimator lags of 0-40 ms, transport delays of 0-20 ms.
"""

from __future__ import annotations

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    return {"effects.torque_lag.tau_s": v["tau_s"], "effects.torque_lag.delay_s": v["delay_s"]}


EFFECT = Effect(
    id="torque_lag",
    title="Motor torque actuator lag and delay",
    params=(
        ParamSpec("tau_s", "s", 0.0, 0.040, 0.0, "first-order lag of the air-gap torque behind the CAN value"),
        ParamSpec("delay_s", "s", 0.0, 0.020, 0.0, "transport delay of the air-gap torque"),
    ),
    vehicle_change=_changes,
    order=30,
)
