"""The paper's two-inertia model (Section 2.1, eqs. 1-6) with the gap-state backlash law.

Equations (per driven wheel; ``n`` equal half-shafts)::

    Jm th_m'' + bm th_m' = Tm - (n / i) Ths                              (1)
    Ths = khs th_s + chs th_s'                                           (2)
    th_s = th_d - th_b,   th_d = th_m / i - th_w                         (3, 4)
    th_b' = max(0, th_d' + khs/chs (th_d - th_b))   if th_b <= -alpha     (5)
            th_d' + khs/chs (th_d - th_b)            if |th_b| < alpha
            min(0, th_d' + khs/chs (th_d - th_b))   if th_b >= +alpha
    Jw th_w'' + bw th_w' = Ths - Thb - Tbx                               (6)

Inside the gap ``th_s`` relaxes with ``th_s' = -(khs/chs) th_s`` so ``Ths == 0`` exactly. The
extracted paper text loses the minus sign in (5); the form above is Nordin's and the only
one that keeps ``th_b`` in ``[-alpha, alpha]``. After each explicit step ``th_b`` is
projected back onto ``[-alpha, alpha]``; the contact tests are ``<=``/``>=`` on the projected
value, never float equality on an unprojected one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numba import njit

from sim.integrate import STATUS_DIVERGED, STATUS_NONFINITE, STATUS_OK, input_at, road_torque
from sim.linear import coupling_rows
from sim.model import ChainModel
from sim.params import Vehicle


@dataclass(frozen=True)
class TwoInertiaParams:
    """Parameters of eqs. 1-6 (SI units; half-shaft values per shaft, wheel values per wheel)."""

    jm: float  # kg m^2, motor plus reducer referred to the motor
    bm: float  # N m s/rad
    ratio: float  # i, motor / wheel speed
    khs: float  # N m/rad per half-shaft (whole driveline in series, real part of its impedance)
    chs: float  # N m s/rad per half-shaft, > 0 (the gap law divides by it; imaginary part / omega)
    alpha: float  # rad, half of the total clearance 2 alpha, in half-shaft angle
    jw: float  # kg m^2 per wheel, I_w + M R^2 / 2
    bw: float = 0.0  # N m s/rad per wheel
    n_shafts: int = 2
    road: tuple[float, ...] = (0.3, 0.0, 0.0, 0.0, 0.0, 0.0)  # as ChainModel.road, whole vehicle

    def max_rate(self) -> float:
        """Largest rate (1/s) of the contact-mode linear system and of the gap relaxation khs/chs."""
        k_m = self.n_shafts * self.khs / self.ratio**2
        w2 = k_m / self.jm + self.khs / self.jw
        return max(math.sqrt(w2), self.khs / self.chs)


def project(vehicle: Vehicle) -> TwoInertiaParams:
    """Reduce the multibody vehicle to eqs. 1-6.

    Reducer inertias are referred to the motor (paper: "equivalent to the motor inertia"), half
    of the half-shaft inertia to each end, and all five clearances summed in half-shaft angle.
    Each coupling is a spring and a damper *in parallel*, and these pairs sit in series, so
    ``khs`` and ``chs`` come from the series sum of the couplings' complex impedances at the
    shuffle frequency (:func:`series_impedance`), with the housing on its mounts as one more
    series element. Adding compliances and "damper compliances" ``1/c`` separately would let
    the stiffest, least damped coupling (the motor spline) set the damping of the whole chain.
    The paper's model has no tyre compliance, linear springs and only viscous drag: tyre slip,
    progressive stiffness and Coulomb drag are left out of the projection. Unequal half-shafts
    enter as the parallel pair (impedances summed, mean lash).
    """
    if vehicle.effects.tyre_slip.enabled:
        vehicle = vehicle.with_changes({"effects.tyre_slip.enabled": False})
    m = vehicle.compiled
    i = vehicle.ratio
    n = vehicle.driven_wheels
    wheel_own = n * vehicle.wheel.inertia + vehicle.body.mass * vehicle.wheel.radius**2
    jw_total = float(sum(m.inertia[w] for w in m.wheels))
    jm = float(sum(m.inertia[b] * m.speed_ratio[b] ** 2 for b in range(m.n_bodies)
                   if b not in (*m.wheels, m.housing)))
    # half-shaft interior nodes count half to each side in this reduction
    extra = jw_total - wheel_own
    jw = (wheel_own + extra) / n
    k_w, c_w = [], []  # each coupling (parallel pairs summed) referred to the wheel angle, all shafts
    alpha_w = 0.0
    right = _right_partners(vehicle, m)  # unequal shafts: the right piece in parallel with the left
    for j in range(m.n_couplings):
        if m.ca[j] == m.housing or j in right.values():
            continue
        p = right.get(j, j)
        k, c = (m.ck[j] + m.ck[p], m.cc[j] + m.cc[p]) if p != j else (m.ck[j], m.cc[j])
        half = 0.5 * (m.chalf[j] + m.chalf[p])
        to_wheel = i * m.speed_ratio[m.ca[j]]  # a-angle per wheel angle
        k_w.append(float(k) * to_wheel**2)
        c_w.append(float(c) * to_wheel**2)
        alpha_w += half / to_wheel
    mount = _housing_element(m)
    k_eq, c_eq, _ = series_impedance(np.array(k_w), np.array(c_w), 1.0 / (i * i * jm) + 1.0 / (n * jw), mount)
    return TwoInertiaParams(
        jm=jm, bm=float(m.rotor_drag[0]), ratio=i,
        khs=k_eq / n, chs=max(c_eq / n, 1e-12), alpha=alpha_w,
        jw=jw, bw=float(m.wheel_drag[0]) * len(m.wheels) / n, n_shafts=n,
        road=tuple(float(x) for x in m.road),
    )


def series_impedance(k: np.ndarray, c: np.ndarray, inv_inertia: float,
                     housing: tuple[float, float, float, float] | None = None,
                     iterations: int = 30) -> tuple[float, float, float]:
    """Equivalent ``(k, c, omega)`` of spring-damper pairs in series, at the mode they carry.

    ``k`` (N m/rad) and ``c`` (N m s/rad) are the pairs referred to one angle; each pair's
    impedance is ``k_j + i omega c_j`` and the chain's is ``1 / sum(1 / (k_j + i omega c_j))``
    (plus ``beta^2 / (k_h + i omega c_h - omega^2 J_h)`` for the housing, ``housing = (beta,
    k_h, c_h, J_h)``: the housing angle moves that angle by ``beta`` per rad, and the housing is
    a grounded mass on its mounts). The equivalent is ``k = Re Z``, ``c = Im Z / omega`` at the
    two-inertia mode ``omega^2 = k * inv_inertia`` (``inv_inertia = 1/J_1 + 1/J_2`` of the two
    ends in the same angle), found by fixed-point iteration (it converges in a few steps:
    ``Z`` varies slowly with ``omega`` below the couplings' own corner frequencies ``k_j/c_j``).
    """
    def impedance(w: float) -> complex:
        y = complex(np.sum(1.0 / (k + 1j * w * c)))
        if housing is not None:
            beta, k_h, c_h, j_h = housing
            y += beta * beta / (k_h + 1j * w * c_h - w * w * j_h)
        return 1.0 / y

    w = math.sqrt(float(1.0 / np.sum(1.0 / k)) * inv_inertia)
    for _ in range(iterations):
        z = impedance(w)
        w_new = math.sqrt(max(z.real, 1e-12) * inv_inertia)
        if abs(w_new - w) <= 1e-12 * w:
            break
        w = w_new
    z = impedance(w)
    return float(z.real), float(z.imag / w), w


def _housing_element(m: ChainModel) -> tuple[float, float, float, float] | None:
    """``(beta, k_h, c_h, J_h)`` of the housing on its mounts as a series element in wheel angle.

    ``beta`` is how far the wheels turn per radian of housing roll with the rotor held and every
    coupling rigid (the gears roll on the housing): found from the chain's deflection rows.
    """
    mounts = [j for j in range(m.n_couplings) if m.ca[j] == m.housing]
    if m.housing < 0 or not mounts:
        return None
    g = coupling_rows(m)
    chain = [j for j in range(m.n_couplings) if j not in mounts]
    free = [b for b in range(m.n_bodies) if b not in (m.rotor, m.housing)]
    x = np.linalg.lstsq(g[np.ix_(chain, free)], -g[chain, m.housing], rcond=None)[0]
    beta = float(np.mean([x[free.index(w)] for w in m.wheels]))
    j = mounts[0]
    return beta, float(m.ck[j]), float(m.cc[j]), float(m.inertia[m.housing])


def _right_partners(vehicle: Vehicle, m: ChainModel) -> dict[int, int]:
    """Left half-shaft coupling -> its right counterpart (unequal shafts), else empty."""
    last = vehicle.chain[-1]
    if last.right is None:
        return {}
    names = list(m.coupling_names)
    return {j: names.index(name.replace(last.name, f"{last.name}_right", 1)) for j, name in enumerate(names)
            if name.startswith(last.name) and not name.startswith(f"{last.name}_right")}


@njit(cache=True, nogil=True)
def run_two_inertia(
    p: np.ndarray, road: np.ndarray, tin: np.ndarray, tq: np.ndarray, linear: bool,
    t0: float, dt: float, n_out: int, sub: int, state0: np.ndarray, speed_limit: float,
    out: np.ndarray, ev_t: np.ndarray, ev_kind: np.ndarray,
) -> tuple[int, float, int]:
    """Integrate eqs. 1-6. ``p = [jm, bm, i, khs, chs, alpha, jw, bw, n]``; ``state0 = [th_m, w_m, th_w, w_w, th_b]``.

    ``out[k] = [w_m, w_w, Ths, gap_open, Tm]`` at ``t0 + k*sub*dt``. Returns ``(status, t, n_events)``.
    """
    jm, bm, ratio, khs, chs, alpha, jw, bw, n = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7], p[8]
    th_m, w_m, th_w, w_w, th_b = state0[0], state0[1], state0[2], state0[3], state0[4]
    k_in = 0
    n_ev = 0
    t = t0
    tm, k_in = input_at(tin, tq, linear, t, k_in)
    th_d = th_m / ratio - th_w
    ths = khs * (th_d - th_b) if (th_b >= alpha or th_b <= -alpha) else 0.0
    was_open = alpha > 0.0 and -alpha < th_b < alpha
    for k in range(n_out):
        if k > 0:
            for _ in range(sub):
                tm, k_in = input_at(tin, tq, linear, t, k_in)
                th_d = th_m / ratio - th_w
                w_d = w_m / ratio - w_w
                drive = w_d + khs / chs * (th_d - th_b)
                if alpha <= 0.0:
                    w_b = 0.0
                elif th_b <= -alpha:
                    w_b = max(0.0, drive)
                elif th_b >= alpha:
                    w_b = min(0.0, drive)
                else:
                    w_b = drive
                if alpha > 0.0 and -alpha < th_b < alpha:
                    ths = 0.0  # the law makes khs th_s + chs th_s' vanish; avoid round-off residue
                else:
                    ths = khs * (th_d - th_b) + chs * (w_d - w_b)
                a_m = (tm - bm * w_m - n / ratio * ths) / jm
                a_w = (ths - bw * w_w - road_torque(road, w_w) / n) / jw
                w_m += dt * a_m
                w_w += dt * a_w
                th_m += dt * w_m
                th_w += dt * w_w
                th_b = min(alpha, max(-alpha, th_b + dt * w_b))  # projection onto the gap
                now_open = alpha > 0.0 and -alpha < th_b < alpha
                if now_open != was_open:
                    was_open = now_open
                    if n_ev < ev_t.size:
                        ev_t[n_ev] = t
                        ev_kind[n_ev] = 1 if now_open else 0
                        n_ev += 1
                t += dt
            if not (math.isfinite(w_m) and math.isfinite(w_w) and math.isfinite(th_b)):
                return STATUS_NONFINITE, t, n_ev
            if abs(w_m) > speed_limit:
                return STATUS_DIVERGED, t, n_ev
        out[k, 0] = w_m
        out[k, 1] = w_w
        out[k, 2] = 0.0 if was_open else ths  # ths is from the step's start; open at its end means 0
        out[k, 3] = 1.0 if was_open else 0.0
        out[k, 4] = tm
    return STATUS_OK, t, n_ev


def pack(p: TwoInertiaParams) -> tuple[np.ndarray, np.ndarray]:
    arr = np.array([p.jm, p.bm, p.ratio, p.khs, p.chs, p.alpha, p.jw, p.bw, float(p.n_shafts)])
    return arr, np.asarray(p.road, dtype=np.float64)


def quasi_static(p: TwoInertiaParams, torque: float, omega_m: float) -> np.ndarray:
    """``[th_m, w_m, th_w, w_w, th_b]`` uniformly accelerating, gap closed on the loaded flank."""
    w_w = omega_m / p.ratio
    road = road_torque(np.asarray(p.road, dtype=np.float64), w_w)
    j_eq = p.jm + p.n_shafts * p.jw / p.ratio**2
    acc_m = (torque - p.bm * omega_m - (road + p.n_shafts * p.bw * w_w) / p.ratio) / j_eq
    ths = (torque - p.bm * omega_m - p.jm * acc_m) * p.ratio / p.n_shafts
    th_b = float(np.sign(ths)) * p.alpha
    th_d = th_b + ths / p.khs
    return np.array([th_d * p.ratio, omega_m, 0.0, w_w, th_b])


__all__ = ["STATUS_DIVERGED", "STATUS_NONFINITE", "STATUS_OK", "TwoInertiaParams", "project", "run_two_inertia",
           "series_impedance"]
