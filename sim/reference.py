"""An independent plain-numpy right-hand side of the chain model for scipy ``solve_ivp``.

This is the accuracy reference for the compiled integrator (tests) and the "obvious
alternative" in the benchmark. It re-implements the forces from the coupling matrix
``G`` (``delta = G theta``) rather than calling the kernel, so a force bug in either shows.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray
from scipy.integrate import solve_ivp

from sim.errors import InstabilityError, ParameterError
from sim.linear import coupling_rows
from sim.model import ChainModel, quasi_static_state

F64 = NDArray[np.float64]
GRAVITY = 9.81


def coupling_matrix(m: ChainModel) -> F64:
    """``G`` (nc x nb) with ``delta = G @ theta`` (the linearisation's own matrix)."""
    return coupling_rows(m)


def contact_torques(m: ChainModel, delta: F64, ddelta: F64) -> F64:
    """Vectorised clamped elasto-backlash law (same definition as :func:`sim.integrate.contact_torque`)."""
    half = m.chalf
    x = np.where(delta > half, delta - half, np.where(delta < -half, delta + half, 0.0))
    tc = m.ck * x + m.ck3 * x**3
    td = m.cc * ddelta
    pos = np.where(td > -tc, tc + np.minimum(tc, td), 0.0)
    neg = np.where(td < -tc, tc + np.maximum(tc, td), 0.0)
    full = m.cramp > 0  # the damper engaging in full over the ramp (contact_damping = "full")
    share = np.minimum(np.abs(x) / np.where(full, m.cramp, 1.0), 1.0)
    pos = np.where(full, np.maximum(tc + td * share, 0.0), pos)
    neg = np.where(full, np.minimum(tc + td * share, 0.0), neg)
    clamped = np.where(delta > half, pos, np.where(delta < -half, neg, 0.0))
    return np.where(half > 0, clamped, m.ck * delta + m.ck3 * delta**3 + td)


def make_rhs(m: ChainModel, t_in: F64, q_in: F64, linear: bool) -> Callable[[float, F64], F64]:
    """``f(t, y)`` with ``y = [theta (nb), omega (nb)]`` for solve_ivp (no tyre slip)."""
    if m.vehicle >= 0:
        raise ParameterError("effects.tyre_slip.enabled", True, "the solve_ivp reference models the classic "
                             "wheel-folded vehicle only")
    G = coupling_matrix(m)
    nb = m.n_bodies
    radius, mass, crr, half_rho_cda, sin_grade, brake = m.road

    def torque(t: float) -> float:
        if linear:
            return float(np.interp(t, t_in, q_in))
        k = int(np.searchsorted(t_in, t, side="right")) - 1
        return float(q_in[min(max(k, 0), q_in.size - 1)])

    def rhs(t: float, y: F64) -> F64:
        theta, omega = y[:nb], y[nb:]
        tau = contact_torques(m, G @ theta, G @ omega)
        f = -G.T @ tau
        tm = torque(t)
        w_r = omega[m.rotor]
        f[m.rotor] += tm - m.rotor_drag[0] * w_r - m.rotor_drag[1] * np.tanh(w_r)
        if m.housing >= 0:
            f[m.housing] -= tm
        share = 1.0 / len(m.wheels)  # unequal shafts: each wheel carries half the car
        for w in m.wheels:
            w_w = omega[w]
            v = w_w * radius
            force = crr * mass * GRAVITY * np.tanh(v / 0.1) + half_rho_cda * v * abs(v) + mass * GRAVITY * sin_grade
            f[w] -= share * (radius * force + brake * np.tanh(w_w / 0.05))
            f[w] -= m.wheel_drag[0] * w_w + m.wheel_drag[1] * np.tanh(w_w / 0.05)
        return np.concatenate((omega, f / m.inertia))

    return rhs


def solve_reference(
    m: ChainModel, t_in: F64, q_in: F64, linear: bool, omega0_rotor: float, t_eval: F64, *,
    method: str = "LSODA", rtol: float = 1e-9, atol: float = 1e-10, max_step: float = np.inf,
) -> tuple[F64, F64, int]:
    """Integrate with solve_ivp from the same quasi-static initial state.

    Returns ``(theta, omega, nfev)`` with shapes (len(t_eval), nb).
    """
    theta0, omega0 = quasi_static_state(m, float(q_in[0]), omega0_rotor)
    sol = solve_ivp(make_rhs(m, t_in, q_in, linear), (float(t_eval[0]), float(t_eval[-1])),
                    np.concatenate((theta0, omega0)), method=method, t_eval=t_eval, rtol=rtol, atol=atol,
                    max_step=max_step)
    if not sol.success:
        raise InstabilityError(f"reference solver failed: {sol.message}")
    nb = m.n_bodies
    return sol.y[:nb].T, sol.y[nb:].T, int(sol.nfev)
