r"""Seat-rail acceleration: what an accelerometer on the cabin floor reads, from the body's translation and its
pitch under the drive unit's mount reaction.

**Why the mounts alone do not change the longitudinal acceleration.** The housing rolls on its mounts about
an axis parallel to the shafts (for a transverse drive unit: the vehicle's lateral axis ``y``). The mount
coupling carries a *torque* ``tau_m`` (housing angle, rotor frame) between the housing and the body; the
mounts' forces on the body add up to a couple (a torque roll restrictor pushes one way, the main mounts the
other). A couple moves no centre of gravity, so the body's longitudinal acceleration stays
``a = F / M`` -- ``SimResult.vehicle_accel_ms2``, with the whole car (drive unit included) in ``M`` -- with
or without mounts. What the mount reaction does is **pitch** the body, and the seat rail, below the centre
of gravity, moves fore and aft with the pitch. The driveline model has no pitch degree of freedom (the
paper's mounts end on fixed ground); ``[body_pitch]`` adds one, driven by the driveline, without feedback.

**Pitch moment** on the sprung body about its centre of gravity (``+y`` = nose down; forward force
``F`` at height ``z`` above the centre of gravity gives ``z F``):

* the mount reaction ``s_w tau_m``: ``+tau_m`` acts on the mount's ground side (the coupling puts
  ``-tau_m`` on the housing), in the rotor's frame, which turns with the wheels (forward roll = ``+y``)
  when ``s_w = +1`` (an even number of external gear pairs) and against them when ``s_w = -1``;
* the wheels pushing the body through the suspension, ``F_hub = M a`` at the wheel-centre height ``R``:
  ``(R - h_cg) M a`` (longitudinal links taken horizontal: no anti-squat or anti-dive geometry; aero,
  grade and the unsprung masses lumped at the centre of gravity).

Quasi-statically the mount reaction is ``-T_w`` (the wheel torque, ``-i T`` with ratio ``i``) and
``T_w = F R + I_w alpha``, so the sum is ``-F h_cg - I_w alpha``: the familiar load-transfer moment of a force
at the road plus the wheels' spin-up. In a transient the mount's roll and the driveline's own momentum
make ``tau_m`` differ from ``-T_w``: that difference, and the load transfer's oscillation, are what the seat
rail feels beyond the body.

**Pitch** ``theta`` (rad, nose down positive) on the suspension, pitch inertia ``I``, natural frequency
``f_p``, damping ratio ``zeta_p``::

    I theta'' + 2 zeta_p w_p I theta' + w_p^2 I theta = M_y(t),      w_p = 2 pi f_p

starting at rest in the equilibrium of the first sample. **Seat-rail acceleration**, along the body's
longitudinal axis at height ``h_s`` (the reading of a body-fixed accelerometer: the tilt puts gravity on
its axis)::

    a_s = a + (h_s - h_cg) theta'' - g theta

With ``h_s = h_cg`` only the tilt remains; in the steady state ``a_s = a - g theta_ss``. The transfer
function from ``M_y`` to ``a_s - a``, ``((h_s - h_cg) s^2 - g) / (I s^2 + c s + k)``, is applied by its
bilinear transform at the output rate (one recursive filter over the run; the pitch mode is near 1 Hz,
far below the output rate, where the transform's frequency warping is negligible).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.model import GRAVITY, ChainModel
from sim.params import Vehicle

F64 = NDArray[np.float64]


def pitch_moment(vehicle: Vehicle, chain: ChainModel, accel_ms2: F64, mount_tau_nm: F64) -> F64:
    """(n,) N m: pitch moment on the body about its centre of gravity, nose down positive (module docstring),
    from the body acceleration (m/s^2) and the mount coupling's torque (N m, housing angle, rotor frame)."""
    bp = vehicle.body_pitch
    lever = vehicle.wheel.radius - bp.cg_height
    return np.asarray(chain.wheel_sense * mount_tau_nm + lever * vehicle.body.mass * accel_ms2, dtype=np.float64)


def seat_rail_acceleration(vehicle: Vehicle, chain: ChainModel, dt: float, accel_ms2: F64,
                           mount_tau_nm: F64) -> F64 | None:
    """(n,) m/s^2 on a uniform grid of spacing ``dt`` (s): the seat-rail acceleration, or None where the
    vehicle has no mount model (housing fixed) or no ``[body_pitch]``."""
    bp = vehicle.body_pitch
    if chain.housing < 0 or not bp.enabled or accel_ms2.size < 2:
        return None
    moment = pitch_moment(vehicle, chain, accel_ms2, mount_tau_nm)
    wp = 2.0 * np.pi * bp.frequency_hz
    den = [bp.inertia, 2.0 * bp.damping_ratio * wp * bp.inertia, wp**2 * bp.inertia]
    num = [bp.seat_rail_height - bp.cg_height, 0.0, -GRAVITY]
    from scipy import signal as sps  # here, not at the top: scipy.signal costs about a second of import

    b, a = sps.bilinear(num, den, fs=1.0 / dt)
    extra, _ = sps.lfilter(b, a, moment, zi=sps.lfilter_zi(b, a) * moment[0])
    return np.asarray(accel_ms2 + extra, dtype=np.float64)
