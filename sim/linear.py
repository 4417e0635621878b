"""Linearised chain: mass/stiffness/damping matrices, state matrix, modes, explicit step limit.

The chain is linearised with every gap closed and no clamping. Progressive springs enter with
their tangent stiffness ``k + 3 k3 x^2`` at a given penetration ``x`` (zero by default). The
relaxation-length tyre is a first-order element, so the exact linearisation needs the state
matrix with the tyre torque as an extra state (:func:`state_matrix`); in the second-order form
(:func:`linear_matrices`) it appears as its spring ``k_t`` (the zero-speed limit).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from sim.model import ChainModel, quasi_static_state, spring_deflection

F64 = NDArray[np.float64]


def coupling_rows(m: ChainModel) -> F64:
    """``G`` (nc x nb) with deflections ``delta = G @ theta``."""
    G = np.zeros((m.n_couplings, m.n_bodies))
    for j in range(m.n_couplings):
        G[j, m.ca[j]] += 1.0
        if m.cb2[j] >= 0:  # 3-body open differential: the mean of both side gears
            G[j, m.cb[j]] -= 0.5 * m.cr[j]
            G[j, m.cb2[j]] -= 0.5 * m.cr[j]
        elif m.cb[j] >= 0:
            G[j, m.cb[j]] -= m.cr[j]
        if m.housing >= 0:
            G[j, m.housing] -= m.ce[j]
    return G


def linear_matrices(m: ChainModel, ck: F64 | None = None) -> tuple[F64, F64, F64]:
    """Mass, stiffness and damping matrices (nb x nb) with every gap closed and no clamping.

    ``ck`` overrides the coupling stiffnesses (e.g. tangent values from :func:`tangent_stiffness`).
    With tyre slip on, the tyre adds its spring ``k_t`` between wheels and vehicle.
    """
    G = coupling_rows(m)
    k = m.ck if ck is None else ck
    K = G.T @ (k[:, None] * G)
    C = G.T @ (m.cc[:, None] * G)
    C[m.rotor, m.rotor] += m.rotor_drag[0]
    for w in m.wheels:
        C[w, w] += m.wheel_drag[0]
    if m.vehicle >= 0:
        g = np.zeros(m.n_bodies)
        g[m.wheel], g[m.vehicle] = 1.0, -1.0
        K += m.tyre[0] * np.outer(g, g)
    return np.diag(m.inertia), K, C


def state_matrix(m: ChainModel, omega_vehicle: float = 0.0, ck: F64 | None = None) -> F64:
    """``A`` of ``x' = A x``, ``x = [theta (nb), omega (nb)]`` (+ tyre torque with tyre slip).

    The tyre's relaxation rate is taken at vehicle speed ``omega_vehicle`` (rad/s of wheel angle);
    road load is left out (its speed derivative is tiny at driveline frequencies).
    """
    nb = m.n_bodies
    M, K, C = linear_matrices(m, ck)
    minv = 1.0 / np.diag(M)
    if m.vehicle < 0:
        return np.block([[np.zeros((nb, nb)), np.eye(nb)], [-minv[:, None] * K, -minv[:, None] * C]])
    g = np.zeros(nb)
    g[m.wheel], g[m.vehicle] = 1.0, -1.0
    K = K - m.tyre[0] * np.outer(g, g)  # the tyre acts through its own state, not as a spring
    A = np.zeros((2 * nb + 1, 2 * nb + 1))
    A[:nb, nb:2 * nb] = np.eye(nb)
    A[nb:2 * nb, :nb] = -minv[:, None] * K
    A[nb:2 * nb, nb:2 * nb] = -minv[:, None] * C
    A[nb:2 * nb, -1] = -g * minv  # -tau_t on the wheels, +tau_t on the vehicle
    A[-1, nb:2 * nb] = m.tyre[0] * g
    A[-1, -1] = -m.tyre[1] * abs(omega_vehicle)
    return A


def modal_frequencies_hz(m: ChainModel, ck: F64 | None = None) -> F64:
    """Undamped natural frequencies (Hz, ascending, rigid-body mode included as ~0)."""
    M, K, _ = linear_matrices(m, ck)
    lam = np.linalg.eigvals(np.linalg.solve(M, K))
    return np.sort(np.sqrt(np.abs(lam.real))) / (2 * np.pi)


def max_rate(m: ChainModel, omega_vehicle: float = 0.0, ck: F64 | None = None) -> float:
    """Largest |eigenvalue| (rad/s) of the damped linear system."""
    return float(np.max(np.abs(np.linalg.eigvals(state_matrix(m, omega_vehicle, ck)))))


def step_limit(m: ChainModel, omega_vehicle: float = 0.0, ck: F64 | None = None) -> float:
    """Largest stable step (s) of semi-implicit Euler on the linearised chain, mode by mode.

    An oscillatory eigenvalue ``|lambda| = omega``, damping ratio ``zeta``, is stable for
    ``h < (2 / omega) (sqrt(1 + zeta^2) - zeta)`` (the scheme's amplification matrix
    ``[[1 - 2 zeta omega h, -omega^2 h], [h (1 - 2 zeta omega h), 1 - omega^2 h^2]]`` has trace
    ``> -1 - det``); a real one ``-sigma`` for ``h < 2 / sigma``. The rigid-body mode is free.
    """
    lam = np.linalg.eigvals(state_matrix(m, omega_vehicle, ck))
    mag = np.abs(lam)
    limits = [np.inf]
    for z, r in zip(lam, mag, strict=True):
        if r <= 1e-9 * mag.max():
            continue
        if abs(z.imag) > 1e-9 * r:
            zeta = max(0.0, -z.real / r)
            limits.append(2.0 / r * (np.sqrt(1.0 + zeta * zeta) - zeta))
        elif z.real < 0:
            limits.append(2.0 / -z.real)
    return float(min(limits))


def tangent_stiffness(m: ChainModel, torque_max: float, overshoot: float = 3.0) -> F64:
    """Tangent stiffness ``k + 3 k3 x^2`` of every coupling at its largest expected penetration.

    The penetration is the one that carries ``overshoot`` times the coupling's quasi-static
    share of ``torque_max`` (N m at the rotor): impacts after a gap closes load a coupling a few
    times its static torque. Without cubic terms this is ``m.ck`` itself.
    """
    if not np.any(m.ck3) or torque_max <= 0:
        return m.ck
    theta, _ = quasi_static_state(m, float(torque_max), 0.0)
    delta = coupling_rows(m) @ theta
    x_static = np.maximum(np.abs(delta) - m.chalf, 0.0)
    tau = overshoot * (m.ck * x_static + m.ck3 * x_static**3)
    x = spring_deflection(m.ck, m.ck3, tau)
    return np.asarray(m.ck + 3.0 * m.ck3 * x**2, dtype=np.float64)
