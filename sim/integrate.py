"""Fixed-step compiled integrator for the chain model (numba, cached on disk).

Scheme: semi-implicit (symplectic) Euler, ``omega += dt * M^-1 F(theta, omega, t)`` then
``theta += dt * omega``, read as leapfrog (speeds at half steps, synchronised for output). It
keeps the energy of the undamped linear part bounded (no drift), costs one force evaluation per
step and is stable below ``dt = 2 / omega_max``; the caller chooses ``dt`` as a fraction of the
limit of the linearised system (:func:`sim.linear.step_limit`).
Sampled torque makes every sample a kink, which ruins the step control of adaptive solvers;
a fixed step does not care.

Contact law (clamped elasto-backlash): inside the dead zone ``|delta| <= alpha`` the torque is
zero; outside, spring ``k x + k3 x^3`` (``x`` the penetration) plus damping ``c d(delta)/dt``, and
the total never pulls (clamped at zero). How the damper engages is the vehicle's ``contact_damping``:
``limited`` (as Modelica's ``ElastoBacklash``, ramp width 0) limits the damping part to the spring
part, so the torque is continuous at contact and a soft, heavily damped compliance is hardly damped
while its penetration is small; ``full`` lets the damper act in full once the penetration exceeds a
small ramp width ``w`` (its share grows as ``x / w`` below it). With ``alpha == 0`` the coupling is a
plain linear spring-damper (both flanks always engaged).

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
def contact_law(delta: float, ddelta: float, k: float, k3: float, c: float, half: float, ramp: float,
                cubic: bool) -> float:
    """Clamped elasto-backlash torque (N m) for deflection ``delta`` and its rate ``ddelta``; ``ramp`` the
    penetration over which the damper engages in full (0: the damping limited to the spring torque).

    ``cubic=False`` leaves the spring's ``k3 x^3`` out (a constant at every call site, so the compiler drops the
    branch): the same number bit for bit where ``k3`` is +0.0 and ``k >= 0``, since ``k3 x^3`` is then a zero
    with the sign of ``x`` and ``k x`` has that sign too, so adding it changes nothing, not even a zero's sign."""
    if half <= 0.0:
        return (k * delta + k3 * delta * delta * delta if cubic else k * delta) + c * ddelta
    if delta > half:
        x = delta - half
        tc = k * x + k3 * x * x * x if cubic else k * x
        td = c * ddelta
        if ramp > 0.0:
            return max(tc + td * min(x / ramp, 1.0), 0.0)
        if td > -tc:
            return tc + min(tc, td)
        return 0.0
    if delta < -half:
        x = delta + half
        tc = k * x + k3 * x * x * x if cubic else k * x
        td = c * ddelta
        if ramp > 0.0:
            return min(tc + td * min(-x / ramp, 1.0), 0.0)
        if td < -tc:
            return tc + max(tc, td)
        return 0.0
    return 0.0


@njit(cache=True, inline="always")
def contact_torque(delta: float, ddelta: float, k: float, k3: float, c: float, half: float, ramp: float) -> float:
    """:func:`contact_law` with the spring's cubic term."""
    return contact_law(delta, ddelta, k, k3, c, half, ramp, True)


@njit(cache=True, inline="always")
def contact_torque_linear(delta: float, ddelta: float, k: float, c: float, half: float, ramp: float) -> float:
    """:func:`contact_law` of a spring without a cubic term (where every ``k3`` is +0.0 and ``k >= 0``)."""
    return contact_law(delta, ddelta, k, 0.0, c, half, ramp, False)


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
    """Rolling, aero and grade load (N m at the wheel axle) at speed ``omega_v * R``, no brake."""
    v = omega_v * road[0]
    # rolling resistance sign, smoothed through standstill; tanh is exactly +-1 in double beyond x = v / 0.1 = 20,
    # and |v| > 2.0000001 m/s is beyond it for certain, so the division is made only near standstill
    if v > 2.0000001:
        sgn = 1.0
    elif v < -2.0000001:
        sgn = -1.0
    else:
        x = v / 0.1
        sgn = 1.0 if x > 20.0 else (-1.0 if x < -20.0 else math.tanh(x))
    force = road[2] * road[1] * GRAVITY * sgn + road[3] * v * abs(v) + road[1] * GRAVITY * road[4]
    return road[0] * force


def is_kernel_layout(ca: np.ndarray, cb: np.ndarray, housing: int) -> bool:
    """True when every coupling but the last joins two bodies and the last (only) is the housing mount."""
    nch = ca.size - (1 if housing >= 0 else 0)
    inner = bool(np.all(cb[:nch] >= 0) and np.all(ca[:nch] != housing))
    return inner and (housing < 0 or (int(ca[nch]) == housing and int(cb[nch]) == -1))


@njit(cache=True, inline="always")
def wheel_load(road: np.ndarray, wheel_drag: np.ndarray, omega_w: float, share: float) -> float:
    """Road load, brake and hub drag (N m) on one wheel body carrying ``share`` of the car."""
    load = road_load_torque(road, omega_w)
    if road[5] != 0.0:
        load += road[5] * math.tanh(omega_w / 0.05)
    load *= share
    if wheel_drag[0] != 0.0 or wheel_drag[1] != 0.0:
        load += wheel_drag[0] * omega_w + wheel_drag[1] * math.tanh(omega_w / 0.05)
    return load


@njit(cache=True)
def _gap_event(j: int, d: float, t: float, dt: float, chalf: np.ndarray, is_open: np.ndarray, d_prev: np.ndarray,
               ev_gap: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray, n_ev: int) -> int:
    """Gap ``j`` opened or closed within the last step: flip its state, log the crossing of
    ``|delta| = alpha`` (time interpolated in the step) while there is room. Returns the event count."""
    now_open = abs(d) < chalf[j]
    is_open[j] = now_open
    if n_ev < ev_gap.size:
        a0 = abs(d_prev[j]) - chalf[j]
        a1 = abs(d) - chalf[j]
        frac = a0 / (a0 - a1) if a0 != a1 else 1.0
        ev_gap[n_ev] = j
        ev_t[n_ev] = t - dt + min(max(frac, 0.0), 1.0) * dt
        ev_kind[n_ev] = 1 if now_open else 0
        n_ev += 1
    return n_ev


@njit(cache=True, nogil=True)
def _initial_forces(
    theta: np.ndarray, omega: np.ndarray, ca: np.ndarray, cb: np.ndarray, cr: np.ndarray, ce: np.ndarray,
    ck: np.ndarray, ck3: np.ndarray, cc: np.ndarray, chalf: np.ndarray, cramp: np.ndarray, cb2: np.ndarray, rotor: int,
    housing: int, wheel: int, wheel2: int, wheel_drag: np.ndarray,
    vehicle: int, road: np.ndarray, rotor_drag: np.ndarray, t_air: float, tyre_tau: float,
    delta: np.ndarray, acc: np.ndarray,
) -> None:
    """Net torque on every body (``acc``) and coupling deflections (``delta``) of one state; same
    forces as the step loop of :func:`run_chain` (kept apart so that loop stays one tight body)."""
    for b in range(acc.size):
        acc[b] = 0.0
    th_h = theta[housing] if housing >= 0 else 0.0
    om_h = omega[housing] if housing >= 0 else 0.0
    for j in range(ca.size):
        a = ca[j]
        bb = cb[j]
        d = theta[a] - ce[j] * th_h
        dd = omega[a] - ce[j] * om_h
        b2 = cb2[j]
        if b2 >= 0:
            d -= cr[j] * (0.5 * (theta[bb] + theta[b2]))
            dd -= cr[j] * (0.5 * (omega[bb] + omega[b2]))
        elif bb >= 0:
            d -= cr[j] * theta[bb]
            dd -= cr[j] * omega[bb]
        f = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j], cramp[j])
        delta[j] = d
        acc[a] -= f
        if b2 >= 0:
            acc[bb] += 0.5 * cr[j] * f
            acc[b2] += 0.5 * cr[j] * f
        elif bb >= 0:
            acc[bb] += cr[j] * f
        if housing >= 0:
            acc[housing] += ce[j] * f
    w_r = omega[rotor]
    acc[rotor] += t_air - rotor_drag[0] * w_r - rotor_drag[1] * math.tanh(w_r / 1.0)
    if housing >= 0:
        acc[housing] -= t_air
    if vehicle >= 0:
        acc[wheel] -= tyre_tau
        acc[vehicle] += tyre_tau - road_load_torque(road, omega[vehicle])
        acc[wheel] -= road[5] * math.tanh(omega[wheel] / 0.05)
        acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 0.0)
    elif wheel2 < 0:
        acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 1.0)
    else:
        acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 0.5)
        acc[wheel2] -= wheel_load(road, wheel_drag, omega[wheel2], 0.5)


@njit(cache=True, nogil=True)
def run_chain(
    inertia: np.ndarray, ca: np.ndarray, cb: np.ndarray, cr: np.ndarray, ce: np.ndarray,
    ck: np.ndarray, ck3: np.ndarray, cc: np.ndarray, chalf: np.ndarray, cramp: np.ndarray, cb2: np.ndarray,
    rotor: int, housing: int, wheel: int, wheel2: int, wheel_drag: np.ndarray, road: np.ndarray,
    rotor_drag: np.ndarray, lag: np.ndarray, sensor_tau: float, vehicle: int, tyre: np.ndarray,
    tin: np.ndarray, tq: np.ndarray, linear: bool,
    t0: float, dt: float, n_out: int, sub: int, theta0: np.ndarray, omega0: np.ndarray, speed_limit: float,
    out_res: np.ndarray, out_sensor: np.ndarray, out_torque: np.ndarray, out_omega: np.ndarray,
    out_tau: np.ndarray, out_open: np.ndarray, ev_gap: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray,
) -> tuple[int, float, int]:
    """Integrate one vehicle; fills the ``out_*`` arrays (row i at ``t0 + i*sub*dt``).

    Leapfrog form of semi-implicit Euler: angles (and the tyre torque) live on the step times,
    speeds half a step earlier; the start takes a half kick back from the given speeds, and each
    output row adds the half kick of the force already computed for the next step, so the
    reported speeds are synchronous with the angles (second order) at no extra force evaluation.

    ``out_omega``/``out_tau``/``out_open`` may have zero rows (batch mode: resolver speed only); with zero rows
    there and zero-length ``ev_*`` too, nothing but the speeds is kept (no coupling torques, gap states or events):
    the same output rows, less work per step.
    ``lag = [delay_s, tau_s]`` of the air-gap torque. Tyre slip (``vehicle >= 0``): ``tyre =
    [k_t, R/sigma, tau_t at t0]``; its torque goes to column ``nc`` of ``out_tau`` if present.
    Gap events (coupling index, time interpolated within the step, 1=open 0=close) go to
    ``ev_*`` up to their length. Returns ``(status, t_fail, n_events)``.

    Coupling ``j`` joins ``ca[j]`` to ``cb[j]`` (and, for the 3-body open differential, to the
    mean of ``cb[j]`` and ``cb2[j]``); the housing mount, if any, is the last coupling and its
    torque is summed in a register. :func:`is_kernel_layout` checks a model. Two wheel bodies
    (``wheel2 >= 0``, unequal half-shafts) each take half of the road load and brake.
    """
    nb = inertia.size
    nc = ca.size
    nch = nc - 1 if housing >= 0 else nc  # chain couplings; the mount (if any) is last
    full = out_omega.shape[0] > 0
    out_tyre = full and out_tau.shape[1] > nc
    # coupling torques and gap states are read (state rows, or room for gap events); without either the serial
    # chain takes the speed-only loop below (the same operations on the speeds, in the same order)
    track = full or ev_gap.size > 0
    theta = theta0.copy()
    omega = omega0.copy()
    acc = np.zeros(nb)
    dtj = np.empty(nb)  # dt / J: one multiply per body and step
    for b in range(nb):
        dtj[b] = dt / inertia[b]
    tau = np.zeros(nc)
    d_prev = np.zeros(nc)
    is_open = np.zeros(nc, dtype=np.bool_)
    tyre_tau = tyre[2] if vehicle >= 0 else 0.0
    serial = True
    for j in range(nch):
        if ca[j] != j or cb[j] != j + 1 or cb2[j] >= 0:
            serial = False
    k_lag = 0
    t_air, k_lag = input_at(tin, tq, linear, t0 - lag[0], k_lag)
    a_lag = 1.0 - math.exp(-dt / lag[1]) if lag[1] > 0.0 else 1.0
    a_sen = 1.0 - math.exp(-dt / sensor_tau) if sensor_tau > 0.0 else 1.0
    c_sen = min(1.0, 0.5 * dt / sensor_tau) if sensor_tau > 0.0 else 1.0
    # start: speeds half a step back, so the first kick lands on the midpoint
    _initial_forces(theta, omega, ca, cb, cr, ce, ck, ck3, cc, chalf, cramp, cb2, rotor, housing, wheel, wheel2,
                    wheel_drag, vehicle, road, rotor_drag, t_air, tyre_tau, d_prev, acc)
    for j in range(nc):
        is_open[j] = chalf[j] > 0.0 and abs(d_prev[j]) < chalf[j]
    for b in range(nb):
        omega[b] -= 0.5 * dtj[b] * acc[b]
    sensor = omega0[rotor] - (omega0[housing] if housing >= 0 else 0.0)
    n_ev = 0
    t = t0
    k = 0
    status = STATUS_OK
    for row in range(n_out):
        n_sub = sub if row < n_out - 1 else 1
        for s in range(n_sub):
            t = t0 + k * dt
            th_h = theta[housing] if housing >= 0 else 0.0
            om_h = omega[housing] if housing >= 0 else 0.0
            t_cmd, k_lag = input_at(tin, tq, linear, t - lag[0], k_lag)
            t_air += a_lag * (t_cmd - t_air)
            for b in range(nch + 1 if serial and not track else 0, nb):  # the speed-only loop sets bodies 0..nch
                acc[b] = 0.0
            acc_h = 0.0  # torque on the housing: mesh reactions, stator, mount
            if serial and not track:  # speed only: each chain body's torque set once, the next one's share carried
                # in a register; acc[j] = (0.0 + cr[j-1] f[j-1]) - f[j] exactly as the loop below accumulates it
                carry = 0.0
                for j in range(nch):
                    d = theta[j] - cr[j] * theta[j + 1] - ce[j] * th_h
                    dd = omega[j] - cr[j] * omega[j + 1] - ce[j] * om_h
                    f = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j], cramp[j])
                    acc[j] = carry - f
                    carry = 0.0 + cr[j] * f
                    acc_h += ce[j] * f
                acc[nch] = carry
            elif serial:  # the usual chain, body j to body j + 1: no index loads in the hot loop
                for j in range(nch):
                    d = theta[j] - cr[j] * theta[j + 1] - ce[j] * th_h
                    dd = omega[j] - cr[j] * omega[j + 1] - ce[j] * om_h
                    f = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j], cramp[j])
                    tau[j] = f
                    acc[j] -= f
                    acc[j + 1] += cr[j] * f
                    acc_h += ce[j] * f
                    if chalf[j] > 0.0:
                        if (abs(d) < chalf[j]) != is_open[j]:
                            n_ev = _gap_event(j, d, t, dt, chalf, is_open, d_prev, ev_gap, ev_t, ev_kind, n_ev)
                        d_prev[j] = d
            else:  # any chain: coupling j joins ca[j] to cb[j], or to the mean of cb[j] and cb2[j]
                for j in range(nch):
                    a = ca[j]
                    bb = cb[j]
                    b2 = cb2[j]
                    if b2 < 0:
                        d = theta[a] - cr[j] * theta[bb] - ce[j] * th_h
                        dd = omega[a] - cr[j] * omega[bb] - ce[j] * om_h
                    else:
                        d = theta[a] - cr[j] * (0.5 * (theta[bb] + theta[b2])) - ce[j] * th_h
                        dd = omega[a] - cr[j] * (0.5 * (omega[bb] + omega[b2])) - ce[j] * om_h
                    f = contact_torque(d, dd, ck[j], ck3[j], cc[j], chalf[j], cramp[j])
                    tau[j] = f
                    acc[a] -= f
                    if b2 < 0:
                        acc[bb] += cr[j] * f
                    else:
                        acc[bb] += 0.5 * cr[j] * f
                        acc[b2] += 0.5 * cr[j] * f
                    acc_h += ce[j] * f
                    if chalf[j] > 0.0:
                        if (abs(d) < chalf[j]) != is_open[j]:
                            n_ev = _gap_event(j, d, t, dt, chalf, is_open, d_prev, ev_gap, ev_t, ev_kind, n_ev)
                        d_prev[j] = d
            if housing >= 0:
                f = contact_torque(th_h, om_h, ck[nch], ck3[nch], cc[nch], 0.0, 0.0)  # mount to ground
                if track:
                    tau[nch] = f
                acc[housing] = acc_h - f - t_air  # ... and the stator reaction
            w_r = omega[rotor]
            ext = t_air - rotor_drag[0] * w_r
            if rotor_drag[1] != 0.0:  # tanh only when there is Coulomb drag
                ext -= rotor_drag[1] * math.tanh(w_r / 1.0)
            acc[rotor] += ext
            if vehicle >= 0:
                acc[wheel] -= tyre_tau
                acc[vehicle] += tyre_tau - road_load_torque(road, omega[vehicle])
                if road[5] != 0.0:
                    acc[wheel] -= road[5] * math.tanh(omega[wheel] / 0.05)
                if wheel_drag[0] != 0.0 or wheel_drag[1] != 0.0:
                    acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 0.0)
            elif wheel2 < 0:
                acc[wheel] -= road_load_torque(road, omega[wheel])
                if road[5] != 0.0:
                    acc[wheel] -= road[5] * math.tanh(omega[wheel] / 0.05)
                if wheel_drag[0] != 0.0 or wheel_drag[1] != 0.0:
                    acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 0.0)
            else:
                acc[wheel] -= wheel_load(road, wheel_drag, omega[wheel], 0.5)
                acc[wheel2] -= wheel_load(road, wheel_drag, omega[wheel2], 0.5)
            if s == 0:  # output row: speeds synchronised with the angles by half of this step's kick
                res = omega[rotor] + 0.5 * dtj[rotor] * acc[rotor]
                if housing >= 0:
                    res -= omega[housing] + 0.5 * dtj[housing] * acc[housing]
                out_res[row] = res
                out_sensor[row] = sensor + c_sen * (res - sensor)
                out_torque[row] = t_air
                if full:
                    for b in range(nb):
                        out_omega[row, b] = omega[b] + 0.5 * dtj[b] * acc[b]
                    for j in range(nc):
                        out_tau[row, j] = tau[j]
                        out_open[row, j] = is_open[j]
                    if out_tyre:
                        out_tau[row, nc] = tyre_tau
                if row == n_out - 1:
                    break
            for b in range(nb):  # kick, drift
                omega[b] += dtj[b] * acc[b]
                theta[b] += dt * omega[b]
            if vehicle >= 0:  # relaxation-length tyre, driven by the new (midpoint) speeds
                w_v = omega[vehicle]
                tyre_tau += dt * (tyre[0] * (omega[wheel] - w_v) - tyre[1] * abs(w_v) * tyre_tau)
            res_half = omega[rotor] - (omega[housing] if housing >= 0 else 0.0)
            sensor += a_sen * (res_half - sensor)
            k += 1
        for b in range(nb):
            if not (math.isfinite(omega[b]) and math.isfinite(theta[b])):
                return STATUS_NONFINITE, t, n_ev
            if abs(omega[b]) > speed_limit:
                return STATUS_DIVERGED, t, n_ev
    return status, t, n_ev


@njit(cache=True, nogil=True)
def run_chain_batch(
    inertia: np.ndarray, ca: np.ndarray, cb: np.ndarray, cr: np.ndarray, ce: np.ndarray,
    ck: np.ndarray, ck3: np.ndarray, cc: np.ndarray, chalf: np.ndarray, cramp: np.ndarray, cb2: np.ndarray,
    rotor: int, housing: int, wheel: int, wheel2: int, wheel_drag: np.ndarray, road: np.ndarray,
    rotor_drag: np.ndarray,
    lag: np.ndarray, sensor_tau: float, vehicle: int, tyre: np.ndarray, tin: np.ndarray, tq: np.ndarray, linear: bool,
    t0: float, dt: np.ndarray, n_out: int, sub: np.ndarray, theta0: np.ndarray, omega0: np.ndarray,
    speed_limit: float, out_res: np.ndarray, ev_gap: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray,
    status: np.ndarray, n_events: np.ndarray, out_body: np.ndarray, body: int,
) -> None:
    """Variant ``v`` uses row ``v`` of every 2-D parameter array (``tyre``: (nv, 3)); resolver speed to
    ``out_res[v]``; the speed (rad/s) of body ``body`` to ``out_body[v]`` when ``out_body`` has rows."""
    nv = inertia.shape[0]
    nb = inertia.shape[1]
    nc = ca.size
    keep = out_body.shape[0] > 0
    rows = n_out if keep else 0
    buf_f = np.zeros((rows, nb))
    buf_t = np.zeros((rows, nc + 1))
    buf_o = np.zeros((rows, nc), dtype=np.bool_)
    sens = np.zeros(n_out)
    torq = np.zeros(n_out)
    for v in range(nv):
        st, _, ne = run_chain(
            inertia[v], ca, cb, cr, ce, ck[v], ck3[v], cc[v], chalf[v], cramp[v], cb2, rotor, housing, wheel, wheel2,
            wheel_drag[v], road[v], rotor_drag[v], lag, sensor_tau, vehicle, tyre[v], tin, tq, linear, t0, dt[v],
            n_out, sub[v],
            theta0[v], omega0[v],
            speed_limit, out_res[v], sens, torq, buf_f, buf_t, buf_o, ev_gap[v], ev_t[v], ev_kind[v],
        )
        status[v] = st
        n_events[v] = ne
        if keep:
            for i in range(n_out):
                out_body[v, i] = buf_f[i, body]
