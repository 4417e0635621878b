"""Equations of motion of the generator's driveline and their fixed-step RK4 integration (numba).

Degrees of freedom, all absolute angles in one sense (the intermediate shaft turns backwards):
rotor, input shaft, intermediate shaft, differential case, differential pinions (spin in side-gear
angle), left/right side gear, left/right half-shaft middle, left/right wheel, housing roll; plus
vehicle speed and one transient tyre slip per wheel. Couplings:

* gear meshes act on angles *relative to the housing*; a mesh's reaction goes into the housing,
  so the housing carries minus the output torque in steady state and the resolver (rotor minus
  housing) sees the roll;
* an **open differential**: side gear = case +- pinion spin, each side-gear contact compliant
  and with its own gap, so the two half-shafts and wheels may turn differently;
* the **contact law** of every gap: zero force inside the clearance; outside, spring on the
  penetration plus a damper that engages linearly over the first 2 % of the clearance of
  penetration and is clamped so the contact never pulls;
* each half-shaft: two springs (the gap in the side-gear half) around a middle inertia, optional
  cubic hardening;
* **tyre**: relaxation-length slip ``sigma kappa' = (omega R - V) - |V| kappa``, force
  ``F_max tanh(C kappa / F_max)``; the body is its own mass behind both tyres with rolling and air
  resistance.

The air-gap torque is an input sampled on the integration grid (actuator effects are applied
before, see :func:`actuator`). Integration: classical RK4, 0.1 ms steps (split into substeps where
the linearised equations' fastest rate needs it, see :func:`substeps`), outputs every 0.5 ms.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from bench.indep.car import Car, tyre_load

DT = 1e-4  # s, integration step
EVERY = 5  # outputs every EVERY steps (2 kHz)
N_STATE = 27
# output columns
OUT = ("speed_rel", "wheel_l", "wheel_r", "body_v", "d_spline", "d_mesh1", "d_mesh2", "d_diff_l", "d_diff_r",
       "d_shaft_l", "d_shaft_r", "housing")
SHAFT_REF = 0.1  # rad: hardening reference twist of a whole half-shaft
MOUNT_REF = 0.02  # rad: hardening reference roll of the housing

_FIELDS = ("j_rotor", "j_input", "j_inter", "j_case", "j_side", "j_pinion", "i1", "i2", "k_spline", "c_spline",
           "k_mesh1", "c_mesh1", "k_mesh2", "c_mesh2", "k_diff", "c_diff", "gap_spline", "gap_mesh1", "gap_mesh2",
           "gap_diff", "gap_shaft", "k_shaft_l", "k_shaft_r", "c_shaft_l", "c_shaft_r", "j_shaft", "j_wheel",
           "radius", "mass", "crr", "cda", "rho", "tyre_c", "tyre_sigma", "j_housing", "k_mount", "c_mount",
           "drag_coulomb", "drag_viscous", "shaft_hardening", "mount_hardening", "ripple_nm")


def pack(car: Car) -> np.ndarray:
    """The car as the kernel's parameter vector (``_FIELDS`` order, then the tyre force limit)."""
    return np.array([float(getattr(car, f)) for f in _FIELDS] + [car.tyre_mu * tyre_load(car)])


@njit(cache=True)
def _contact(d: float, v: float, k: float, c: float, gap: float) -> float:
    """Elasto-backlash force: free inside +-gap/2, spring + ramped, clamped damper outside."""
    a = 0.5 * gap
    if d > a:
        p = d - a
    elif d < -a:
        p = d + a
    else:
        return 0.0
    ramp = min(abs(p) / (0.02 * gap + 1e-12), 1.0)
    f = k * p + c * v * ramp
    if p > 0.0:
        return max(f, 0.0)
    return min(f, 0.0)


@njit(cache=True)
def _rhs(x: np.ndarray, tq: float, P: np.ndarray, dx: np.ndarray) -> None:
    (jm, jin, jint, jc, js, jp, i1, i2, ksp, csp, km1, cm1, km2, cm2, kd, cd, gsp, gm1, gm2, gd, gs,
     ksl, ksr, csl, csr, jsh, jw, R, m, crr, cda, rho, tc, sig, jh, kmt, cmt, dc, dv, hs, hm, rip, fmax) = (
        P[0], P[1], P[2], P[3], P[4], P[5], P[6], P[7], P[8], P[9], P[10], P[11], P[12], P[13], P[14], P[15],
        P[16], P[17], P[18], P[19], P[20], P[21], P[22], P[23], P[24], P[25], P[26], P[27], P[28], P[29], P[30],
        P[31], P[32], P[33], P[34], P[35], P[36], P[37], P[38], P[39], P[40], P[41], P[42])
    am, ain, aint, ac, ap, al, ar, asl, asr, awl, awr, ah = (x[0], x[1], x[2], x[3], x[4], x[5], x[6], x[7],
                                                             x[8], x[9], x[10], x[11])
    wm, win, wint, wc, wp, wl, wr, wsl, wsr, wwl, wwr, wh = (x[12], x[13], x[14], x[15], x[16], x[17], x[18],
                                                             x[19], x[20], x[21], x[22], x[23])
    vb, kl, kr = x[24], x[25], x[26]
    # motor: air-gap torque (+ first-order ripple) and drag act between rotor and stator (housing)
    rel = wm - wh
    t_air = tq + rip * np.sin(am - ah)
    t_drag = dc * rel / np.sqrt(rel * rel + 1.0) + dv * rel
    f_sp = _contact(am - ain, wm - win, ksp, csp, gsp)
    d1 = (ain - ah) / i1 + (aint - ah)
    f1 = _contact(d1, (win - wh) / i1 + (wint - wh), km1, cm1, gm1)
    d2 = -(aint - ah) / i2 - (ac - ah)
    f2 = _contact(d2, -(wint - wh) / i2 - (wc - wh), km2, cm2, gm2)
    fl = _contact(ac + ap - al, wc + wp - wl, kd, cd, gd)
    fr = _contact(ac - ap - ar, wc - wp - wr, kd, cd, gd)
    # half-shafts: gap + spring 2k in the side-gear half, spring 2k in the wheel half
    xl1, xr1 = al - asl, ar - asr
    hl1 = _contact(xl1, wl - wsl, 2 * ksl * (1 + hs * (2 * xl1 / SHAFT_REF) ** 2), 2 * csl, gs)
    hr1 = _contact(xr1, wr - wsr, 2 * ksr * (1 + hs * (2 * xr1 / SHAFT_REF) ** 2), 2 * csr, gs)
    xl2, xr2 = asl - awl, asr - awr
    hl2 = 2 * ksl * xl2 * (1 + hs * (2 * xl2 / SHAFT_REF) ** 2) + 2 * csl * (wsl - wwl)
    hr2 = 2 * ksr * xr2 * (1 + hs * (2 * xr2 / SHAFT_REF) ** 2) + 2 * csr * (wsr - wwr)
    # tyres and body
    vv = max(abs(vb), 0.5)
    ftl = fmax * np.tanh(tc * kl / fmax)
    ftr = fmax * np.tanh(tc * kr / fmax)
    f_road = crr * m * 9.81 * np.tanh(vb / 0.1) + 0.5 * rho * cda * vb * abs(vb)
    mount = kmt * ah * (1 + hm * (ah / MOUNT_REF) ** 2) + cmt * wh
    for i in range(12):
        dx[i] = x[12 + i]
    dx[12] = (t_air - t_drag - f_sp) / jm
    dx[13] = (f_sp - f1 / i1) / jin
    dx[14] = (-f1 + f2 / i2) / jint
    dx[15] = (f2 - fl - fr) / jc
    dx[16] = (-fl + fr) / jp
    dx[17] = (fl - hl1) / js
    dx[18] = (fr - hr1) / js
    dx[19] = (hl1 - hl2) / jsh
    dx[20] = (hr1 - hr2) / jsh
    dx[21] = (hl2 - R * ftl) / jw
    dx[22] = (hr2 - R * ftr) / jw
    dx[23] = (-t_air + t_drag + f1 * (1 / i1 + 1) - f2 * (1 / i2 + 1) - mount) / jh
    dx[24] = (ftl + ftr - f_road) / m
    dx[25] = ((wwl * R - vb) - vv * kl) / sig
    dx[26] = ((wwr * R - vb) - vv * kr) / sig


@njit(cache=True)
def _outputs(x: np.ndarray, P: np.ndarray, row: np.ndarray) -> None:
    i1, i2 = P[6], P[7]
    row[0] = x[12] - x[23]
    row[1] = x[21]
    row[2] = x[22]
    row[3] = x[24]
    row[4] = x[0] - x[1]
    row[5] = (x[1] - x[11]) / i1 + (x[2] - x[11])
    row[6] = -(x[2] - x[11]) / i2 - (x[3] - x[11])
    row[7] = x[3] + x[4] - x[5]
    row[8] = x[3] - x[4] - x[6]
    row[9] = x[5] - x[7]
    row[10] = x[6] - x[8]
    row[11] = x[11]


@njit(cache=True)
def _integrate(x0: np.ndarray, tq: np.ndarray, P: np.ndarray, dt: float, every: int) -> np.ndarray:
    n = tq.size - 1
    out = np.empty((n // every + 1, 12))
    x = x0.copy()
    k1 = np.empty(N_STATE)
    k2 = np.empty(N_STATE)
    k3 = np.empty(N_STATE)
    k4 = np.empty(N_STATE)
    y = np.empty(N_STATE)
    _outputs(x, P, out[0])
    for s in range(n):
        ta, tb = tq[s], tq[s + 1]
        tm = 0.5 * (ta + tb)
        _rhs(x, ta, P, k1)
        for i in range(N_STATE):
            y[i] = x[i] + 0.5 * dt * k1[i]
        _rhs(y, tm, P, k2)
        for i in range(N_STATE):
            y[i] = x[i] + 0.5 * dt * k2[i]
        _rhs(y, tm, P, k3)
        for i in range(N_STATE):
            y[i] = x[i] + dt * k3[i]
        _rhs(y, tb, P, k4)
        for i in range(N_STATE):
            x[i] += dt * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]) / 6.0
        if (s + 1) % every == 0:
            _outputs(x, P, out[(s + 1) // every])
    return out


@njit(cache=True)
def _ramp_lag(u: np.ndarray, a: float, b: float) -> np.ndarray:
    """Ramp-invariant first-order lag: y_k = a y_(k-1) + b u_k + (1 - a - b) u_(k-1)."""
    y = np.empty_like(u)
    y[0] = u[0]
    for k in range(1, u.size):
        y[k] = a * y[k - 1] + b * u[k] + (1 - a - b) * u[k - 1]
    return y


def initial_state(car: Car, speed_kmh: float) -> np.ndarray:
    """Every body turning at the speed of a vehicle at ``speed_kmh``, gaps centred, no load."""
    v = speed_kmh / 3.6
    ww = v / car.radius
    x = np.zeros(N_STATE)
    x[12] = x[13] = ww * car.i1 * car.i2
    x[14] = -ww * car.i2
    x[15] = x[17] = x[18] = x[19] = x[20] = x[21] = x[22] = ww
    x[24] = v
    return x


RK4_LIMIT = 2.5  # |lambda| h below which RK4 is stable on every eigenvalue (real axis: 2.78, imaginary: 2.83)


def substeps(car: Car, speed_kmh: float = 30.0) -> int:
    """RK4 steps per ``DT`` that keep the integration stable on the car's fastest linearised rate.

    The nominal cars need one; a heavily damped data sheet (the half-shaft damper on the light side
    gear) needs more.
    """
    fastest = float(np.max(np.abs(linear_modes(car, speed_kmh))))
    return max(1, int(np.ceil(fastest * DT / RK4_LIMIT)))


def actuator(car: Car, t: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """Air-gap torque on the grid ``t`` (uniform): CAN torque after dead time and first-order lag (exact
    discretisation of ``tau T' = T_in - T`` for a piecewise-linear input)."""
    out = np.interp(t - car.lag_dead, t, torque, left=torque[0])
    if car.lag_tau <= 0:
        return out
    h = float(t[1] - t[0])
    a = np.exp(-h / car.lag_tau)
    b = 1 - car.lag_tau / h * (1 - a)
    return _ramp_lag(out, a, b)


def simulate(car: Car, t: np.ndarray, torque: np.ndarray, speed_kmh: float,
             settle_s: float = 2.0) -> dict[str, np.ndarray]:
    """Run the driveline on the CAN torque ``torque`` (N m, uniform grid ``t`` of step DT, s).

    The first ``settle_s`` seconds are run at the drive's first torque before ``t[0]`` so that the
    gaps sit where that load puts them; returns the output columns (``OUT``) at ``t[::EVERY]``.
    """
    if not np.allclose(np.diff(t), DT):
        raise ValueError("torque must be on the integration grid (step DT)")
    n_settle = round(settle_s / DT)
    tq = np.concatenate([np.full(n_settle, torque[0]), torque])
    tt = np.arange(tq.size) * DT
    air = actuator(car, tt, tq)
    sub = substeps(car, speed_kmh)
    if sub > 1:  # the air-gap torque is piecewise linear between grid points
        air = np.interp(np.arange((tq.size - 1) * sub + 1) * (DT / sub), tt, air)
    out = _integrate(initial_state(car, speed_kmh), air, pack(car), DT / sub, EVERY * sub)
    out = out[n_settle // EVERY:]
    return {name: out[:, i].copy() for i, name in enumerate(OUT)} | {"t": t[::EVERY][: out.shape[0]]}


def linear_modes(car: Car, speed_kmh: float = 30.0) -> np.ndarray:
    """Eigenvalues (1/s) of the equations of motion linearised with every contact engaged.

    Every clearance is set to zero and the state is put where every contact is pressed on its
    drive flank (1 mrad), all bodies turning at ``speed_kmh`` and no tyre slip; the Jacobian of
    :func:`_rhs` is taken by central differences (the equations are linear there: the contact
    dampers fully engaged, hardening zero at the reference twist of the shafts' wheel halves).
    """
    P = pack(car.with_(gap_spline=0.0, gap_mesh1=0.0, gap_mesh2=0.0, gap_diff=0.0, gap_shaft=0.0))
    x0 = initial_state(car, speed_kmh)
    d = 1e-3
    x0[1] = x0[0] - d  # spline: rotor ahead of the input shaft
    x0[2] = d - x0[1] / car.i1  # mesh 1
    x0[3] = -x0[2] / car.i2 - d  # mesh 2
    x0[5] = x0[6] = x0[3] - d  # side-gear contacts
    x0[7] = x0[8] = x0[5] - d  # half-shafts' side-gear halves
    x0[9] = x0[10] = x0[7]
    n = N_STATE
    jac = np.empty((n, n))
    fp, fm = np.empty(n), np.empty(n)
    for i in range(n):
        h = 1e-7 * max(1.0, abs(x0[i]))
        xp, xm = x0.copy(), x0.copy()
        xp[i] += h
        xm[i] -= h
        _rhs(xp, 0.0, P, fp)
        _rhs(xm, 0.0, P, fm)
        jac[:, i] = (fp - fm) / (2 * h)
    return np.linalg.eigvals(jac)


def first_mode(car: Car, speed_kmh: float = 30.0) -> tuple[float, float, float]:
    """(natural frequency Hz, damping ratio, damped frequency Hz) of the lowest oscillatory mode."""
    lam = linear_modes(car, speed_kmh)
    osc = lam[lam.imag > 2 * np.pi * 0.3]
    z = osc[np.argmin(np.abs(osc))]
    wn = float(np.abs(z))
    return wn / (2 * np.pi), float(-z.real / wn), float(z.imag / (2 * np.pi))
