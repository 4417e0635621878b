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
here (gap * r, stiffness / r^2). Reported coupling torques are those at the driven member.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from sim.params import GAP_NAMES, Vehicle

F64 = NDArray[np.float64]
GRAVITY = 9.81


@dataclass(frozen=True)
class ChainModel:
    """Compiled-kernel view of a vehicle. Arrays: ``nb`` bodies, ``nc`` couplings."""

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
    gap_coupling: dict[str, int]  # gap name -> coupling index
    rotor: int
    housing: int  # -1 when the housing is fixed
    wheel: int
    speed_ratio: F64  # (nb,) omega_k / omega_rotor for a rigid chain (housing: 0)
    road: F64  # (6,) radius, mass, rolling coeff, 0.5*rho*CdA, sin(grade), brake torque
    rotor_drag: F64  # (2,) viscous N m s/rad, Coulomb N m

    @property
    def n_bodies(self) -> int:
        return int(self.inertia.size)

    @property
    def n_couplings(self) -> int:
        return int(self.ca.size)


def build_chain(v: Vehicle) -> ChainModel:
    """Bodies and couplings of the multibody model for ``v`` (see the module docstring)."""
    red, hs, n = v.reducer, v.halfshaft, v.halfshaft.count
    r1, r2 = red.ratio1, red.ratio2
    seg = hs.segments
    j_seg = n * hs.inertia / seg  # both shafts' inertia per segment
    names = ["rotor", "input_shaft", "intermediate", "differential", "side_gears"]
    inertia = [v.motor.rotor_inertia, red.input_shaft_inertia, red.intermediate_inertia,
               red.differential_inertia, red.side_gears_inertia + 0.5 * j_seg]
    names += [f"halfshaft_node{i}" for i in range(1, seg)]
    inertia += [j_seg] * (seg - 1)
    wheel_j = n * v.wheel.inertia + v.body.mass * v.wheel.radius**2 + 0.5 * j_seg  # I_W = I_w + M R^2 / 2 per wheel
    names.append("wheels")
    inertia.append(wheel_j)
    wheel = len(names) - 1
    housing = -1
    if v.housing.enabled:
        names.append("housing")
        inertia.append(v.housing.inertia)
        housing = len(names) - 1

    g = v.gaps
    k_seg, c_seg = n * hs.stiffness * seg, n * hs.damping * seg
    # name, a, b, r, e, k (a angle), c (a angle), half gap (a angle), report factor
    rows: list[tuple[str, int, int, float, float, float, float, float, float]] = [
        ("spline", 0, 1, 1.0, 0.0, red.spline_stiffness, red.spline_damping, g.spline.nominal / 2, 1.0),
        ("gear1", 1, 2, r1, 1.0 + r1, red.mesh1_stiffness / r1**2, red.mesh1_damping / r1**2,
         g.mesh1.nominal * r1 / 2, r1),
        ("gear2", 2, 3, r2, -(1.0 + r2), red.mesh2_stiffness / r2**2, red.mesh2_damping / r2**2,
         g.mesh2.nominal * r2 / 2, r2),
        ("diff", 3, 4, 1.0, 0.0, red.diff_stiffness, red.diff_damping, g.differential.nominal / 2, 1.0),
    ]
    chain_nodes = [4, *range(5, 5 + seg - 1), wheel]
    for i in range(seg):
        name = "halfshaft" if seg == 1 else f"halfshaft{i + 1}"
        half = g.halfshaft.nominal / 2 if i == 0 else 0.0
        rows.append((name, chain_nodes[i], chain_nodes[i + 1], 1.0, 0.0, k_seg, c_seg, half, 1.0))
    if housing >= 0:
        rows.append(("mount", housing, -1, 1.0, 0.0, v.housing.mount_stiffness, v.housing.mount_damping, 0.0, -1.0))
    cols = list(zip(*rows, strict=True))

    ratio = np.zeros(len(names))
    ratio[0] = 1.0
    for _, a, b, r, *_rest in rows:
        if b >= 0 and a != housing:
            ratio[b] = ratio[a] / r
    half_rho_cda = 0.5 * v.body.air_density * v.body.drag_area
    sin_grade = float(np.sin(np.arctan(v.body.grade_percent / 100.0)))
    eff = v.effects.drag
    return ChainModel(
        body_names=tuple(names),
        inertia=np.asarray(inertia, dtype=np.float64),
        coupling_names=tuple(cols[0]),
        ca=np.asarray(cols[1], dtype=np.int64),
        cb=np.asarray(cols[2], dtype=np.int64),
        cr=np.asarray(cols[3], dtype=np.float64),
        ce=np.asarray(cols[4], dtype=np.float64) * (1.0 if housing >= 0 else 0.0),
        ck=np.asarray(cols[5], dtype=np.float64),
        ck3=np.zeros(len(rows)),
        cc=np.asarray(cols[6], dtype=np.float64),
        chalf=np.asarray(cols[7], dtype=np.float64),
        creport=np.asarray(cols[8], dtype=np.float64),
        gap_coupling={name: i for i, name in enumerate(GAP_NAMES)},
        rotor=0,
        housing=housing,
        wheel=wheel,
        speed_ratio=ratio,
        road=np.array([v.wheel.radius, v.body.mass, v.body.rolling_resistance, half_rho_cda, sin_grade,
                       v.body.brake_torque]),
        rotor_drag=np.array([v.motor.viscous_damping + eff.viscous_nms, eff.coulomb_nm]),
    )


def road_torque(road: F64, omega_w: float) -> float:
    """Road load at the wheels (N m) for wheel speed ``omega_w`` (rad/s); mirrors the kernel."""
    radius, mass, crr, half_rho_cda, sin_grade, brake = road
    v = omega_w * radius
    force = crr * mass * GRAVITY * np.tanh(v / 0.1) + half_rho_cda * v * abs(v) + mass * GRAVITY * sin_grade
    return float(radius * force + brake * np.tanh(omega_w / 0.05))


def linear_matrices(m: ChainModel) -> tuple[F64, F64, F64]:
    """Mass, stiffness and damping matrices (nb x nb) with every gap closed and no clamping."""
    nb = m.n_bodies
    K = np.zeros((nb, nb))
    C = np.zeros((nb, nb))
    for j in range(m.n_couplings):
        g = np.zeros(nb)
        g[m.ca[j]] += 1.0
        if m.cb[j] >= 0:
            g[m.cb[j]] -= m.cr[j]
        if m.housing >= 0:
            g[m.housing] -= m.ce[j]
        K += m.ck[j] * np.outer(g, g)
        C += m.cc[j] * np.outer(g, g)
    C[m.rotor, m.rotor] += m.rotor_drag[0]
    return np.diag(m.inertia), K, C


def modal_frequencies_hz(m: ChainModel) -> F64:
    """Undamped natural frequencies (Hz, ascending, rigid-body mode included as ~0)."""
    M, K, _ = linear_matrices(m)
    lam = np.linalg.eigvals(np.linalg.solve(M, K))
    return np.sort(np.sqrt(np.abs(lam.real))) / (2 * np.pi)


def max_rate(m: ChainModel) -> float:
    """Largest |eigenvalue| (rad/s) of the damped linear system; sets the explicit step."""
    M, K, C = linear_matrices(m)
    nb = m.n_bodies
    Minv = np.diag(1.0 / np.diag(M))
    A = np.block([[np.zeros((nb, nb)), np.eye(nb)], [-Minv @ K, -Minv @ C]])
    return float(np.max(np.abs(np.linalg.eigvals(A))))


def quasi_static_state(m: ChainModel, torque: float, omega_rotor: float) -> tuple[F64, F64]:
    """Angles and speeds of the uniformly accelerating driveline under motor torque ``torque``.

    Every body turns at ``omega_rotor * speed_ratio``; each coupling carries the torque that
    accelerates the bodies downstream of it against the road load, so each gap sits closed on
    the flank that torque loads (centred when the torque is exactly zero). The housing is at
    rest, deflected on its mounts by the reaction. The wheel angle is the zero reference.
    """
    nb = m.n_bodies
    ratio = m.speed_ratio
    omega = omega_rotor * ratio
    drag = m.rotor_drag[0] * omega_rotor + m.rotor_drag[1] * np.tanh(omega_rotor / 1.0)
    load = road_torque(m.road, float(omega[m.wheel]))
    j_eq = float(np.sum(m.inertia * ratio**2))  # housing has ratio 0
    acc0 = (torque - drag - load * ratio[m.wheel]) / j_eq
    tau = np.zeros(m.n_couplings)
    inflow = np.zeros(nb)
    inflow[m.rotor] = torque - drag
    for j in range(m.n_couplings):  # couplings are listed in chain order, rotor first
        a, b = m.ca[j], m.cb[j]
        if a == m.housing:
            continue
        tau[j] = inflow[a] - m.inertia[a] * acc0 * ratio[a]
        inflow[b] += m.cr[j] * tau[j]
    theta_h = 0.0
    if m.housing >= 0:
        reaction = -torque + float(np.sum(m.ce * tau))
        j_mount = int(np.nonzero(m.ca == m.housing)[0][0])
        theta_h = reaction / m.ck[j_mount]
        tau[j_mount] = reaction
    theta = np.zeros(nb)
    if m.housing >= 0:
        theta[m.housing] = theta_h
    for j in range(m.n_couplings - 1, -1, -1):
        a, b = m.ca[j], m.cb[j]
        if a == m.housing:
            continue
        delta = np.sign(tau[j]) * m.chalf[j] + tau[j] / m.ck[j]
        theta[a] = delta + m.cr[j] * theta[b] + m.ce[j] * theta_h
    return theta, omega


def deflections(m: ChainModel, theta: F64) -> F64:
    """Coupling deflections ``delta_j`` (rad, in a's angle) for body angles ``theta``."""
    b_theta = np.where(m.cb >= 0, theta[np.maximum(m.cb, 0)], 0.0)
    h_theta = theta[m.housing] if m.housing >= 0 else 0.0
    return np.asarray(theta[m.ca] - m.cr * b_theta - m.ce * h_theta, dtype=np.float64)
