"""Optional effects of the vehicle description (``[effects.*]`` tables), all off by default.

Each is a frozen dataclass whose numeric fields carry unit and rule (see :mod:`sim.fields`);
at their defaults the model is exactly the paper's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from sim.fields import NONNEG, POS, flag
from sim.fields import num as _f

SECONDS = (0.0, 10.0)  # delays, time constants and sample periods of a drive's signals
CUBIC_STIFFNESS = (0.0, 1e14)  # N m/rad^3: doubles a 1e9 N m/rad mesh at 3 mrad


@dataclass(frozen=True, kw_only=True)
class TorqueLag:
    """Air-gap torque = first-order lag (tau) of the CAN torque delayed by ``delay_s``. Off at zeros."""

    delay_s: float = _f("s", NONNEG, 0.0, SECONDS)
    tau_s: float = _f("s", NONNEG, 0.0, SECONDS)


@dataclass(frozen=True, kw_only=True)
class SpeedSensor:
    """Inverter speed signal: first-order filter, transport delay, sample-and-hold, quantisation. Off at zeros."""

    tau_s: float = _f("s", NONNEG, 0.0, SECONDS)
    delay_s: float = _f("s", NONNEG, 0.0, SECONDS)
    sample_s: float = _f("s", NONNEG, 0.0, SECONDS)
    resolution_rpm: float = _f("rpm", NONNEG, 0.0, (0.0, 1e4))


@dataclass(frozen=True, kw_only=True)
class Drag:
    """Extra rotor drag: Coulomb (bearing/seal/churning) plus viscous. Off at zeros."""

    coulomb_nm: float = _f("N m", NONNEG, 0.0, (0.0, 1e4))
    viscous_nms: float = _f("N m s/rad", NONNEG, 0.0, (0.0, 1e6))


@dataclass(frozen=True, kw_only=True)
class ProgressiveStiffness:
    """Cubic (hardening) term ``k3 x^3`` added to each coupling spring ``k x``. Off at zeros.

    Each value is in its coupling's own angle like the linear stiffness it hardens (N m/rad^3):
    ``spline`` motor angle, ``mesh1``/``mesh2`` the driven gear, ``differential`` side gears,
    ``halfshaft`` per shaft, ``mount`` housing roll. Negative (softening) values are rejected:
    the spring would lose stiffness and turn over at large deflection.
    """

    spline: float = _f("N m/rad^3 (motor angle)", NONNEG, 0.0, CUBIC_STIFFNESS)
    mesh1: float = _f("N m/rad^3 (intermediate angle)", NONNEG, 0.0, CUBIC_STIFFNESS)
    mesh2: float = _f("N m/rad^3 (differential angle)", NONNEG, 0.0, CUBIC_STIFFNESS)
    differential: float = _f("N m/rad^3 (side-gear angle)", NONNEG, 0.0, CUBIC_STIFFNESS)
    halfshaft: float = _f("N m/rad^3 (per shaft)", NONNEG, 0.0, CUBIC_STIFFNESS)
    mount: float = _f("N m/rad^3 (housing roll)", NONNEG, 0.0, CUBIC_STIFFNESS)

    @property
    def any(self) -> bool:
        return any(getattr(self, f.name) != 0.0 for f in dataclasses.fields(self))


@dataclass(frozen=True, kw_only=True)
class TyreSlip:
    """Tyre longitudinal compliance: the vehicle mass as its own body behind the tyres. Off by default.

    Force per driven tyre with slip stiffness ``C`` and relaxation length ``sigma``::

        dF/dt = (C / sigma) (omega_w R - V) - (|V| / sigma) F

    (a spring ``C/sigma`` N/m in series with a speed-dependent damper ``C/|V|``). Off, the
    vehicle is folded into the wheel inertia (I_W = I_w + M R^2 / 2 per wheel) as in the paper.
    """

    enabled: bool = flag(False)
    slip_stiffness: float = _f("N per unit slip, per driven tyre", POS, 8.0e4, (1e3, 1e10))
    relaxation_length: float = _f("m", POS, 0.15, (0.01, 5.0))


@dataclass(frozen=True, kw_only=True)
class Effects:
    torque_lag: TorqueLag = field(default_factory=TorqueLag)
    speed_sensor: SpeedSensor = field(default_factory=SpeedSensor)
    drag: Drag = field(default_factory=Drag)
    progressive_stiffness: ProgressiveStiffness = field(default_factory=ProgressiveStiffness)
    tyre_slip: TyreSlip = field(default_factory=TyreSlip)
