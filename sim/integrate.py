"""Fixed-step compiled integrator for the chain model (numba, cached on disk).

Scheme: semi-implicit (symplectic) Euler, ``omega += dt * M^-1 F(theta, omega, t)`` then
``theta += dt * omega``. It keeps the energy of the undamped linear part bounded (no drift),
costs one force evaluation per step and is stable below ``dt = 2 / omega_max``; the caller
chooses ``dt`` as a fraction of that from the linearised system (:func:`sim.model.max_rate`).
Sampled torque makes every sample a kink, which ruins the step control of adaptive solvers;
a fixed step does not care.

Contact law (clamped elasto-backlash, as Modelica's ``ElastoBacklash``): inside the dead zone
``|delta| <= alpha`` the torque is zero; outside, spring ``k x + k3 x^3`` (``x`` the
penetration) plus damping ``c d(delta)/dt``, where the damping part is limited to the spring
part (continuous torque at contact) and the total never pulls (clamped at zero). With
``alpha == 0`` the coupling is a plain linear spring-damper (both flanks always engaged).

Status codes returned by the kernels: 0 ok, 1 non-finite state, 2 diverging speed.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

STATUS_OK = 0
STATUS_NONFINITE = 1
STATUS_DIVERGED = 2
GRAVITY = 9.81


@njit(cache=True, inline="always")
def contact_torque(delta: float, ddelta: float, k: float, k3: float, c: float, half: float) -> float:
    """Clamped elasto-backlash torque (N m) for deflection ``delta`` and its rate ``ddelta``."""
    if half <= 0.0:
        return k * delta + k3 * delta * delta * delta + c * ddelta
    if delta > half:
        x = delta - half
        tc = k * x + k3 * x * x * x
        td = c * ddelta
        if td > -tc:
            return tc + min(tc, td)
        return 0.0
    if delta < -half:
        x = delta + half
        tc = k * x + k3 * x * x * x
        td = c * ddelta
        if td < -tc:
            return tc + max(tc, td)
        return 0.0
    return 0.0


@njit(cache=True, inline="always")
def input_at(tin: np.ndarray, tq: np.ndarray, linear: bool, t: float, k: int) -> tuple[float, int]:
    """Torque at time ``t`` from samples (hold or linear); ``k`` is a moving cursor (t non-decreasing)."""
    n = tin.size
    while k + 1 < n and tin[k + 1] <= t:
        k += 1
    if t <= tin[0]:
        return tq[0], 0
    if k + 1 >= n:
        return tq[n - 1], k
    if linear:
        w = (t - tin[k]) / (tin[k + 1] - tin[k])
        return tq[k] + w * (tq[k + 1] - tq[k]), k
    return tq[k], k


@njit(cache=True, inline="always")
def road_torque(road: np.ndarray, omega_w: float) -> float:
    """Road load plus brake (N m at the wheels) with the vehicle folded into the wheels."""
    v = omega_w * road[0]
    force = road[2] * road[1] * GRAVITY * math.tanh(v / 0.1) + road[3] * v * abs(v) + road[1] * GRAVITY * road[4]
    return road[0] * force + road[5] * math.tanh(omega_w / 0.05)


@njit(cache=True, inline="always")
def road_load_torque(road: np.ndarray, omega_v: float) -> float:
    """Rolling, aero and grade load (N m at the wheel axle) on the vehicle body (tyre slip on)."""
    v = omega_v * road[0]
    force = road[2] * road[1] * GRAVITY * math.tanh(v / 0.1) + road[3] * v * abs(v) + road[1] * GRAVITY * road[4]
    return road[0] * force


@njit(cache=True)
def run_chain(
    inertia: np.ndarray, ca: np.ndarray, cb: np.ndarray, cr: np.ndarray, ce: np.ndarray,
    ck: np.ndarray, ck3: np.ndarray, cc: np.ndarray, chalf: np.ndarray,
    rotor: int, housing: int, wheel: int, road: np.ndarray, rotor_drag: np.ndarray,
    lag: np.ndarray, sensor_tau: float, vehicle: int, tyre: np.ndarray,
    tin: np.ndarray, tq: np.ndarray, linear: bool,
    t0: float, dt: float, n_out: int, sub: int, theta0: np.ndarray, omega0: np.ndarray, speed_limit: float,
    out_res: np.ndarray, out_sensor: np.ndarray, out_torque: np.ndarray, out_omega: np.ndarray,
    out_tau: np.ndarray, out_open: np.ndarray, ev_gap: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray,
) -> tuple[int, float, int]:
    """Integrate one vehicle; fills the ``out_*`` arrays (row i at ``t0 + i*sub*dt``).

    ``out_omega``/``out_tau``/``out_open`` may have zero rows (batch mode: resolver speed only).
    ``lag = [delay_s, tau_s]`` of the air-gap torque. Tyre slip (``vehicle >= 0``): ``tyre =
    [k_t, R/sigma, tau_t at t0]``; its torque goes to column ``nc`` of ``out_tau`` if present.
    Gap events (coupling index, time, 1=open 0=close) go to ``ev_*`` up to their length.
    Returns ``(status, t_fail, n_events)``.
    """
    nb = inertia.size
    nc = ca.size
    full = out_omega.shape[0] > 0
    theta = theta0.copy()
    omega = omega0.copy()
    acc = np.zeros(nb)
    tau = np.zeros(nc)
    is_open = np.zeros(nc, dtype=np.bool_)
    for j in range(nc):
        d = theta[ca[j]] - (cr[j] * theta[cb[j]] if cb[j] >= 0 else 0.0)
        dd = omega[ca[j]] - (cr[j] * omega[cb[j]] if cb[j] >= 0 else 0.0)
        if housing >= 0:
            d -= ce[j] * theta[housing]
            dd -= ce[j] * omega[housing]
        is_open[j] = chalf[j] > 0.0 and abs(d) < chalf[j]
        tau[j] = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j])
    k_in = 0
    k_lag = 0
    t_air, k_in = input_at(tin, tq, linear, t0 - lag[0], k_in)
    a_lag = 1.0 - math.exp(-dt / lag[1]) if lag[1] > 0.0 else 1.0
    a_sen = 1.0 - math.exp(-dt / sensor_tau) if sensor_tau > 0.0 else 1.0
    res = omega[rotor] - (omega[housing] if housing >= 0 else 0.0)
    sensor = res
    n_ev = 0
    t = t0
    tyre_tau = tyre[2] if vehicle >= 0 else 0.0
    out_tyre = full and out_tau.shape[1] > nc
    for i in range(n_out):
        if i > 0:
            for _ in range(sub):
                t_cmd, k_lag = input_at(tin, tq, linear, t - lag[0], k_lag)
                t_air += a_lag * (t_cmd - t_air)
                for b in range(nb):
                    acc[b] = 0.0
                for j in range(nc):
                    a = ca[j]
                    bb = cb[j]
                    d = theta[a]
                    dd = omega[a]
                    if bb >= 0:
                        d -= cr[j] * theta[bb]
                        dd -= cr[j] * omega[bb]
                    if housing >= 0:
                        d -= ce[j] * theta[housing]
                        dd -= ce[j] * omega[housing]
                    f = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j])
                    tau[j] = f
                    acc[a] -= f
                    if bb >= 0:
                        acc[bb] += cr[j] * f
                    if housing >= 0:
                        acc[housing] += ce[j] * f
                    if chalf[j] > 0.0:
                        now_open = abs(d) < chalf[j]
                        if now_open != is_open[j]:
                            is_open[j] = now_open
                            if n_ev < ev_gap.size:
                                ev_gap[n_ev] = j
                                ev_t[n_ev] = t
                                ev_kind[n_ev] = 1 if now_open else 0
                                n_ev += 1
                w_r = omega[rotor]
                acc[rotor] += t_air - rotor_drag[0] * w_r - rotor_drag[1] * math.tanh(w_r / 1.0)
                if housing >= 0:
                    acc[housing] -= t_air
                if vehicle >= 0:
                    acc[wheel] -= tyre_tau + road[5] * math.tanh(omega[wheel] / 0.05)
                    acc[vehicle] += tyre_tau - road_load_torque(road, omega[vehicle])
                else:
                    acc[wheel] -= road_torque(road, omega[wheel])
                for b in range(nb):
                    omega[b] += dt * acc[b] / inertia[b]
                    theta[b] += dt * omega[b]
                if vehicle >= 0:  # relaxation-length tyre, driven by the updated speeds
                    w_v = omega[vehicle]
                    tyre_tau += dt * (tyre[0] * (omega[wheel] - w_v) - tyre[1] * abs(w_v) * tyre_tau)
                res = omega[rotor] - (omega[housing] if housing >= 0 else 0.0)
                sensor += a_sen * (res - sensor)
                t += dt
            for b in range(nb):
                if not (math.isfinite(omega[b]) and math.isfinite(theta[b])):
                    return STATUS_NONFINITE, t, n_ev
                if abs(omega[b]) > speed_limit:
                    return STATUS_DIVERGED, t, n_ev
        out_res[i] = res
        out_sensor[i] = sensor
        out_torque[i] = t_air
        if full:
            for b in range(nb):
                out_omega[i, b] = omega[b]
            for j in range(nc):
                out_tau[i, j] = tau[j]
                out_open[i, j] = is_open[j]
            if out_tyre:
                out_tau[i, nc] = tyre_tau
    return STATUS_OK, t, n_ev


@njit(cache=True)
def run_chain_batch(
    inertia: np.ndarray, ca: np.ndarray, cb: np.ndarray, cr: np.ndarray, ce: np.ndarray,
    ck: np.ndarray, ck3: np.ndarray, cc: np.ndarray, chalf: np.ndarray,
    rotor: int, housing: int, wheel: int, road: np.ndarray, rotor_drag: np.ndarray,
    lag: np.ndarray, sensor_tau: float, vehicle: int, tyre: np.ndarray, tin: np.ndarray, tq: np.ndarray, linear: bool,
    t0: float, dt: np.ndarray, n_out: int, sub: np.ndarray, theta0: np.ndarray, omega0: np.ndarray,
    speed_limit: float, out_res: np.ndarray, ev_gap: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray,
    status: np.ndarray, n_events: np.ndarray,
) -> None:
    """Variant ``v`` uses row ``v`` of every 2-D parameter array (``tyre``: (nv, 3)); resolver speed to
    ``out_res[v]``."""
    nv = inertia.shape[0]
    nb = inertia.shape[1]
    nc = ca.size
    dummy_f = np.zeros((0, nb))
    dummy_t = np.zeros((0, nc))
    dummy_o = np.zeros((0, nc), dtype=np.bool_)
    sens = np.zeros(n_out)
    torq = np.zeros(n_out)
    for v in range(nv):
        st, _, ne = run_chain(
            inertia[v], ca, cb, cr, ce, ck[v], ck3[v], cc[v], chalf[v], rotor, housing, wheel, road[v],
            rotor_drag[v], lag, sensor_tau, vehicle, tyre[v], tin, tq, linear, t0, dt[v], n_out, sub[v],
            theta0[v], omega0[v],
            speed_limit, out_res[v], sens, torq, dummy_f, dummy_t, dummy_o, ev_gap[v], ev_t[v], ev_kind[v],
        )
        status[v] = st
        n_events[v] = ne
