"""The multibody driveline as a chain of rigid bodies joined by (elasto-backlash) couplings.

Bodies and couplings, built from a :class:`~sim.params.Vehicle` (paper Figure 3)::

      stator reaction -T                        mounts k_h, c_h
            |                                        |
    [H] housing  <-- mesh reactions (1+r) tau ------ ground
            :
    T -> [0] rotor =(1 spline)= [1] input =(2 mesh 27/79)= [2] intermediate =(3 mesh 20/77)= [3] differential
                                                                                                 ||(4 differential)
         [W] wheels + vehicle =(hs seg n)= ... =(hs seg 2)= [5] half-shaft node =(5 half-shaft)= [4] side gears
          |
        road load (rolling, aero, grade) + brake

State: absolute angles ``theta`` and speeds ``omega`` of every body (rad, rad/s), each in the
body's own *drive sense* (positive when the vehicle drives forward), so the mass matrix is
diagonal. Coupling ``j`` joins body ``a`` to body ``b`` (``b = -1``: ground) with ratio ``r``
and a housing coefficient ``e``; its deflection in ``a``'s angle is::

    delta_j = theta_a - r_j * theta_b - e_j * theta_H

For an external gear pair the gear centres sit in the housing, so the mesh rolls on the
*relative* angles and ``e = s_a (1 + r)`` (``s_a = +-1`` is the true turning sense of ``a``);
coaxial couplings have ``e = 0``. By virtual work the coupling torque ``tau_j`` acts as
``-tau`` on ``a``, ``+r tau`` on ``b`` and ``+e tau`` on the housing, so the mesh reactions
and the stator's ``-T`` make the housing roll on its mounts, and the resolver (stator-fixed)
reads ``omega_0 - omega_H``.

Every coupling stores its values in ``a``'s angle; the Vehicle gives each gap and mesh
stiffness in its *own* shaft's angle (gear pairs: the driven gear) and they are converted
here (gap * r, stiffness / r^2, cubic stiffness / r^4). Reported coupling torques are those at
the driven member.

Optional tyre slip (``effects.tyre_slip``): the vehicle mass becomes its own body [V] (inertia
``M R^2`` in wheel angle, speed ``V / R``) behind the tyres, and the road load acts on it. The
tyre torque ``tau_t`` (all driven tyres, at the wheel axle) is a state of its own::

    d tau_t / dt = k_t (omega_W - omega_V) - (R / sigma) |omega_V| tau_t,   k_t = n C R^2 / sigma

the relaxation-length tyre: a spring ``k_t`` in series with a damper ``n C R^2 / |V|``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from sim.stagekinds.base import ChainBuilder, Wiring

if TYPE_CHECKING:
    from sim.params import Vehicle

F64 = NDArray[np.float64]
GRAVITY = 9.81
# contact_damping = "full": a contact's damper engages over this share of its half clearance of penetration (a
# smooth start; the motor speed hardly depends on it: 0.01 to 0.5 moved a heavily damped chain car's reversals by
# under 0.5 rpm RMS)
CONTACT_RAMP = 0.1


@dataclass(frozen=True)
class ChainModel:
    """Compiled-kernel view of a vehicle. Arrays: ``nb`` bodies, ``nc`` couplings.

    Read-only (arrays and the gap table): one is built per :class:`~sim.params.Vehicle` object
    (:attr:`Vehicle.compiled <sim.params.Vehicle.compiled>`) and shared by every simulation of it.
    """

    body_names: tuple[str, ...]
    inertia: F64  # (nb,) kg m^2
    coupling_names: tuple[str, ...]
    ca: NDArray[np.int64]  # (nc,) body a
    cb: NDArray[np.int64]  # (nc,) body b, -1 = ground
    cr: F64  # (nc,) ratio omega_a / omega_b
    ce: F64  # (nc,) housing coefficient
    ck: F64  # (nc,) stiffness, N m/rad in a's angle
    ck3: F64  # (nc,) cubic stiffness term, N m/rad^3 (progressive stiffness; 0 = linear)
    cc: F64  # (nc,) damping, N m s/rad in a's angle
    chalf: F64  # (nc,) half clearance alpha in a's angle, rad (0 = no backlash)
    creport: F64  # (nc,) factor from tau (a side) to the reported torque at the driven member
    gap_coupling: Mapping[str, int]  # gap name -> coupling index
    rotor: int
    housing: int  # -1 when the housing is fixed
    wheel: int
    speed_ratio: F64  # (nb,) omega_k / omega_rotor for a rigid chain (housing: 0)
    road: F64  # (6,) radius, mass, rolling coeff, 0.5*rho*CdA, sin(grade), brake torque
    rotor_drag: F64  # (2,) viscous N m s/rad, Coulomb N m
    vehicle: int = -1  # vehicle body behind the tyres (tyre slip on), -1 = folded into the wheels
    tyre: F64 = field(default_factory=lambda: np.zeros(2))  # (2,) k_t N m/rad, R/sigma 1/rad
    # open differential with unequal shafts: coupling j drives b and b2 (delta uses their mean), -1 = none
    cb2: NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    wheel2: int = -1  # second wheel body (unequal shafts): each wheel carries half the car and road load
    wheel_drag: F64 = field(default_factory=lambda: np.zeros(2))  # (2,) per wheel body: N m s/rad, N m
    wheel_sense: float = 1.0  # true turning sense of the wheels in the rotor's (and the housing angle's) frame
    # (nc,) penetration over which a contact's damper engages in full, rad in a's angle; 0 = the damping limited to
    # the spring torque (the vehicle's contact_damping, sim.integrate's contact law)
    cramp: F64 = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        if self.cb2.size != self.ca.size:
            object.__setattr__(self, "cb2", np.full(self.ca.size, -1, dtype=np.int64))
        if self.cramp.size != self.ca.size:
            object.__setattr__(self, "cramp", np.zeros(self.ca.size))
        object.__setattr__(self, "gap_coupling", MappingProxyType(dict(self.gap_coupling)))
        for f in fields(self):
            value = getattr(self, f.name)
            if isinstance(value, np.ndarray):
                value.flags.writeable = False

    @property
    def n_bodies(self) -> int:
        return int(self.inertia.size)

    @property
    def n_couplings(self) -> int:
        return int(self.ca.size)

    @property
    def wheels(self) -> tuple[int, ...]:
        return (self.wheel,) if self.wheel2 < 0 else (self.wheel, self.wheel2)

    def b_angle(self, theta: F64) -> F64:
        """Angle of each coupling's b side (mean of both side gears for the 3-body differential; 0: ground)."""
        b = np.where(self.cb >= 0, theta[np.maximum(self.cb, 0)], 0.0)
        two = self.cb2 >= 0
        return np.asarray(np.where(two, 0.5 * (b + theta[np.maximum(self.cb2, 0)]), b), dtype=np.float64)


def build_chain(v: Vehicle) -> ChainModel:
    """Bodies and couplings of the multibody model for ``v`` (see the module docstring).

    Works on :attr:`Vehicle.chain`, so a classic file and its stage equivalent give the same
    arrays. Each stage's kind appends its body and coupling (:meth:`sim.stagekinds.StageKind.wire`,
    values converted from their stated shaft to the input shaft); the wheel end, the vehicle
    body, the housing and its mount are added around them here.
    """
    stages = v.chain
    tyre = v.effects.tyre_slip
    n = v.driven_wheels
    bld = ChainBuilder()
    w = Wiring(bld=bld, cur=bld.body("rotor", v.motor.rotor_inertia), driven_wheels=n,
               wheel_inertia=v.wheel.inertia, own=n * v.wheel.inertia,
               vehicle_inertia=0.0 if tyre.enabled else v.body.mass * v.wheel.radius**2,
               split=stages[-1].right is not None)
    for s in stages:
        s.spec.wire(w, s, s.body_name or s.name, s.coupling_name or s.name)
    if w.wheel < 0:  # the last stage drives the wheels directly
        bld.names[w.cur] = "wheels"
        bld.inertia[w.cur] += w.own + w.vehicle_inertia
        w.wheel = w.cur
    return _finish(v, bld, w.wheel, w.wheel2, w.own / v.wheel.inertia, w.sense)


def _finish(v: Vehicle, bld: ChainBuilder, wheel: int, wheel2: int, per_body: float, sense: float = 1.0) -> ChainModel:
    """Vehicle body, housing and mount, ratios and road data around the built chain."""
    tyre = v.effects.tyre_slip
    vehicle = bld.body("vehicle", v.body.mass * v.wheel.radius**2) if tyre.enabled else -1
    housing = bld.body("housing", v.housing.inertia) if v.housing.enabled else -1
    if housing >= 0:
        bld.couple("mount", housing, -1, 1.0, 0.0, v.housing.mount_stiffness, v.housing.mount_damping, 0.0, -1.0,
                   v.effects.progressive_stiffness.mount)
    cols = list(zip(*bld.rows, strict=True))
    ratio = np.zeros(len(bld.names))
    ratio[0] = 1.0
    for _, a, b, b2, r, *_rest in bld.rows:
        if b >= 0 and a != housing:
            ratio[b] = ratio[a] / r
        if b2 >= 0:
            ratio[b2] = ratio[a] / r
    if vehicle >= 0:
        ratio[vehicle] = ratio[wheel]
    half_rho_cda = 0.5 * v.body.air_density * v.body.drag_area
    sin_grade = float(np.sin(np.arctan(v.body.grade_percent / 100.0)))
    eff = v.effects.drag
    n = v.driven_wheels
    return ChainModel(
        body_names=tuple(bld.names),
        inertia=np.asarray(bld.inertia, dtype=np.float64),
        coupling_names=tuple(cols[0]),
        ca=np.asarray(cols[1], dtype=np.int64),
        cb=np.asarray(cols[2], dtype=np.int64),
        cb2=np.asarray(cols[3], dtype=np.int64),
        cr=np.asarray(cols[4], dtype=np.float64),
        ce=np.asarray(cols[5], dtype=np.float64) * (1.0 if housing >= 0 else 0.0),
        ck=np.asarray(cols[6], dtype=np.float64),
        cc=np.asarray(cols[7], dtype=np.float64),
        chalf=np.asarray(cols[8], dtype=np.float64),
        cramp=CONTACT_RAMP * np.asarray(cols[8], dtype=np.float64) if v.contact_damping == "full"
        else np.zeros(len(cols[8])),
        creport=np.asarray(cols[9], dtype=np.float64),
        ck3=np.asarray(cols[10], dtype=np.float64),
        gap_coupling=dict(bld.gaps),
        rotor=0,
        housing=housing,
        wheel=wheel,
        wheel2=wheel2,
        speed_ratio=ratio,
        road=np.array([v.wheel.radius, v.body.mass, v.body.rolling_resistance, half_rho_cda, sin_grade,
                       v.body.brake_torque]),
        rotor_drag=np.array([v.motor.viscous_damping + eff.viscous_nms, v.motor.coulomb_drag + eff.coulomb_nm]),
        wheel_drag=np.array([per_body * v.wheel.viscous_drag, per_body * v.wheel.coulomb_drag]),
        vehicle=vehicle,
        wheel_sense=sense,
        tyre=np.array([n * tyre.slip_stiffness * v.wheel.radius**2 / tyre.relaxation_length,
                       v.wheel.radius / tyre.relaxation_length]) if tyre.enabled else np.zeros(2),
    )


def road_torque(road: F64, omega_w: float) -> float:
    """Road load plus brake at the wheels (N m) for wheel speed ``omega_w`` (rad/s); mirrors the kernel."""
    return road_load_torque(road, omega_w) + brake_torque(road, omega_w)


def road_load_torque(road: F64, omega_v: float) -> float:
    """Rolling, aero and grade load (N m at the wheel axle) at vehicle speed ``omega_v * R``."""
    radius, mass, crr, half_rho_cda, sin_grade, _ = road
    v = omega_v * radius
    force = crr * mass * GRAVITY * np.tanh(v / 0.1) + half_rho_cda * v * abs(v) + mass * GRAVITY * sin_grade
    return float(radius * force)


def brake_torque(road: F64, omega_w: float) -> float:
    """Brake torque (N m) at wheel speed ``omega_w``, smoothed through zero speed."""
    return float(road[5] * np.tanh(omega_w / 0.05))


def quasi_static_state(m: ChainModel, torque: float, omega_rotor: float) -> tuple[F64, F64]:
    """Angles and speeds of the uniformly accelerating driveline under motor torque ``torque``.

    Every body turns at ``omega_rotor * speed_ratio``; each coupling carries the torque that
    accelerates the bodies downstream of it against the road load, so each gap sits closed on
    the flank that torque loads (centred when the torque is exactly zero). The housing is at
    rest, deflected on its mounts by the reaction. The wheel angle is the zero reference.
    With tyre slip the vehicle runs behind the wheels by the steady slip of the tyre torque
    (:func:`quasi_static_full` also returns that torque).
    """
    theta, omega, _ = quasi_static_full(m, torque, omega_rotor)
    return theta, omega


def spring_deflection(k: F64, k3: F64, tau: F64) -> F64:
    """Penetration ``x`` with ``k x + k3 x^3 = tau`` (elementwise; unique since k > 0, k3 >= 0)."""
    linear = tau / k
    if not np.any(k3):
        return np.asarray(linear, dtype=np.float64)
    x = linear
    for _ in range(60):  # Newton from the linear guess: monotone for a hardening spring
        f = k * x + k3 * x**3 - tau
        step = f / (k + 3.0 * k3 * x**2)
        x = x - step
        if np.all(np.abs(step) <= 1e-15 * (1.0 + np.abs(x))):
            break
    return np.asarray(np.where(k3 == 0.0, linear, x), dtype=np.float64)


def quasi_static_full(m: ChainModel, torque: float, omega_rotor: float) -> tuple[F64, F64, float]:
    """:func:`quasi_static_state` plus the tyre torque state (N m, 0 without tyre slip)."""
    nb = m.n_bodies
    ratio = m.speed_ratio
    omega = omega_rotor * ratio
    drag = m.rotor_drag[0] * omega_rotor + m.rotor_drag[1] * np.tanh(omega_rotor / 1.0)
    w_w = float(omega[m.wheel])
    load = road_torque(m.road, w_w)
    if np.any(m.wheel_drag):  # hub drag of every wheel body, as in the kernel
        load += len(m.wheels) * (m.wheel_drag[0] * w_w + m.wheel_drag[1] * np.tanh(w_w / 0.05))
    j_eq = float(np.sum(m.inertia * ratio**2))  # housing has ratio 0
    acc0 = (torque - drag - load * ratio[m.wheel]) / j_eq
    tyre_tau = 0.0
    if m.vehicle >= 0:  # the tyre accelerates the vehicle body against the road load
        tyre_tau = m.inertia[m.vehicle] * acc0 * ratio[m.vehicle] + road_load_torque(m.road, w_w)
        s = m.tyre[1] * tyre_tau / m.tyre[0]  # steady slip: omega_W - omega_V = s |omega_V|
        denom = 1.0 + s if w_w >= 0 else 1.0 - s
        omega[m.vehicle] = w_w / denom if denom > 0 else w_w
    tau = np.zeros(m.n_couplings)
    inflow = np.zeros(nb)
    inflow[m.rotor] = torque - drag
    for j in range(m.n_couplings):  # couplings are listed in chain order, rotor first
        a, b = m.ca[j], m.cb[j]
        if a == m.housing:
            continue
        tau[j] = inflow[a] - m.inertia[a] * acc0 * ratio[a]
        if m.cb2[j] >= 0:  # open differential: equal split to both side gears
            inflow[b] += 0.5 * m.cr[j] * tau[j]
            inflow[m.cb2[j]] += 0.5 * m.cr[j] * tau[j]
        else:
            inflow[b] += m.cr[j] * tau[j]
    theta_h = 0.0
    mount = np.flatnonzero(m.ca == m.housing) if m.housing >= 0 else np.zeros(0, dtype=np.int64)
    if mount.size:
        j_mount = int(mount[0])
        tau[j_mount] = -torque + float(np.sum(m.ce * tau))
        theta_h = float(spring_deflection(m.ck[j_mount:j_mount + 1], m.ck3[j_mount:j_mount + 1],
                                          tau[j_mount:j_mount + 1])[0])
    x = spring_deflection(m.ck, m.ck3, tau)
    theta = np.zeros(nb)
    if m.housing >= 0:
        theta[m.housing] = theta_h
    for j in range(m.n_couplings - 1, -1, -1):
        a, b = m.ca[j], m.cb[j]
        if a == m.housing:
            continue
        delta = np.sign(tau[j]) * m.chalf[j] + x[j]
        theta_b = theta[b] if m.cb2[j] < 0 else 0.5 * (theta[b] + theta[m.cb2[j]])
        theta[a] = delta + m.cr[j] * theta_b + m.ce[j] * theta_h
    return theta, omega, tyre_tau


def deflections(m: ChainModel, theta: F64) -> F64:
    """Coupling deflections ``delta_j`` (rad, in a's angle) for body angles ``theta``."""
    b_theta = m.b_angle(theta)
    h_theta = theta[m.housing] if m.housing >= 0 else 0.0
    return np.asarray(theta[m.ca] - m.cr * b_theta - m.ce * h_theta, dtype=np.float64)
