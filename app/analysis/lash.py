r"""Gap-open time from measured speed and torque: the interval in which the motor runs as a free rotor.

While every flank is in contact the motor drives the whole vehicle; while a backlash is open
it drives only what lies on its side of the gap: the rotor and the reducer gears, of inertia
``J`` (motor-referred, from the vehicle description) -- about 1/30 of the loaded inertia, so
the speed slope changes by that factor. With ``S`` the shaft torque the rotor feels,
``J dw/dt = T - S``; the *free-rotor residual*

    r(t) = d * (n(t) - 30 / (pi J) * integral(T dt))          (rpm; d = +1 tip-in, -1 tip-out)

has slope ``-d S / J``. It rises while the driveline still carries the old torque (``S`` runs
towards zero as the torque reverses), is flat while the gap is open (``S = 0``), and falls
sharply at the impact, when ``S`` jumps to carry the new torque::

      r ^          t_open            t_close
        |            .----------------.            plateau: the motor accelerates as T/J
        |          .'                  \
        |        .'  loss of load       \  impact (kink, steep fall)
        |      .'                        \
        +-------------------------------------> t

Model fitted by least squares on ``[t_open - pre_s, t_close + post_s]``::

    r = P + A min(0, t - t_open)^2 + E w(t) + B max(0, t - t_close) + C max(0, t - t_close)^2

``A <= 0`` (the load fading linearly to zero: a tangent entry), ``B <= 0`` (a kink down), and
``w = q(min(t, t_close)) - q(t_open)`` after ``t_open`` (0 before) with ``q`` the torque-integral
term: ``1 + E`` rescales the free-rotor inertia to ``J / (1 + E)``, bounded to ``inertia_range``,
so a vehicle file whose rotor inertia is off by 10-30 % tilts the plateau instead of moving its
ends. The rise and the fall must each exceed ``min_step_rpm`` and a quarter of the other.
For every candidate pair ``(t_open, t_close)`` the fit is linear; the Gram matrix is assembled
from prefix sums (the basis functions of the two ends have disjoint support), so a grid of
pairs costs one batched 5x5 solve: a coarse grid (the sample period, at least 2 ms), then a
fine one (a quarter period, at most 0.25 ms) around the best pair. The criterion is the
residual variance ``SSE / (n - 7)`` (windows differ in length).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.analysis.series import FloatArray
from app.signals import Signal
from sim.units import RPM_PER_RAD_S

NAN = float("nan")


@dataclass(frozen=True)
class LashParams:
    open_search_s: tuple[float, float] = (-0.05, 0.10)  # loss of load searched this long around the crossing
    close_search_s: tuple[float, float] = (-0.04, 0.25)  # impact searched here
    pre_s: float = 0.03  # approach fitted over this long before the loss of load ...
    post_s: float = 0.03  # ... and the fall over this long after the impact
    min_step_rpm: float = 5.0  # the rise and the fall must each exceed this (and 5x the noise)
    inertia_range: tuple[float, float] = (0.7, 1.4)  # allowed (1 + E): free-rotor inertia J / (1 + E)


@dataclass(frozen=True)
class GapOpen:
    """Where the motor ran as a free rotor; NaN fields when no such interval was found."""

    t_open_s: float  # loss of load (the driveline torque reaches zero)
    t_close_s: float  # impact (the load comes back)
    rotor_inertia_kgm2: float  # inertia the speed slope implies on the plateau, J / (1 + E)
    fit_rms_rpm: float

    @property
    def duration_s(self) -> float:
        return self.t_close_s - self.t_open_s


NO_GAP = GapOpen(NAN, NAN, NAN, NAN)


def _torque_integral(t: FloatArray, torque: Signal) -> FloatArray:
    """Cumulative trapezoid integral of the torque (N m s) at ``t``, on the union of both time bases."""
    inner = torque.t[(torque.t > t[0]) & (torque.t < t[-1])]
    tt = np.union1d(t, inner)
    tq = torque.at(tt)
    ok = np.isfinite(tq)
    if not ok.any():
        return np.full(t.size, NAN)
    tq = np.interp(tt, tt[ok], tq[ok])
    cum = np.concatenate(([0.0], np.cumsum(0.5 * (tq[1:] + tq[:-1]) * np.diff(tt))))
    return np.asarray(np.interp(t, tt, cum), dtype=np.float64)


def _fit_grid(t: FloatArray, r: FloatArray, q: FloatArray, ta: FloatArray, tb: FloatArray, p: LashParams,
              min_step: float) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Residual variance (inf where infeasible), shape (len(ta), len(tb)), and coefficients (..., 5)."""

    def prefix(x: FloatArray) -> FloatArray:
        return np.concatenate(([0.0], np.cumsum(x)))

    def between(c: FloatArray, i: npt.NDArray[np.intp], j: npt.NDArray[np.intp]) -> FloatArray:
        return np.asarray(c[j] - c[i], dtype=np.float64)

    c1, cr, crr, cq, cqq, cqr = (prefix(x) for x in (np.ones_like(r), r, r * r, q, q * q, q * r))
    lo = np.searchsorted(t, ta - p.pre_s)[:, None]
    ia = np.searchsorted(t, ta)[:, None]
    ib = np.searchsorted(t, tb, side="right")[None, :]
    hi = np.searchsorted(t, tb + p.post_s, side="right")[None, :]
    qa, qb = np.interp(ta, t, q)[:, None], np.interp(tb, t, q)[None, :]
    n, s_r, s_rr = between(c1, lo, hi), between(cr, lo, hi), between(crr, lo, hi)
    valid = ib >= ia
    n_ab = np.where(valid, between(c1, ia, ib), 0.0)
    sq_ab, sqq_ab, sqr_ab, sr_ab = (np.where(valid, between(c, ia, ib), 0.0) for c in (cq, cqq, cqr, cr))
    n_bh, sr_bh = between(c1, ib, hi), between(cr, ib, hi)
    dq = qb - qa
    s_w = sq_ab - n_ab * qa + n_bh * dq
    s_ww = sqq_ab - 2.0 * qa * sq_ab + n_ab * qa**2 + n_bh * dq**2
    s_wr = sqr_ab - qa * sr_ab + dq * sr_bh
    # approach term: support [t_open - pre, t_open); fall terms: (t_close, t_close + post]
    u = np.minimum(0.0, t[None, :] - ta[:, None])
    u2 = np.where(t[None, :] >= ta[:, None] - p.pre_s, u * u, 0.0)
    su2, su4, su2r = (x[:, None] for x in (u2.sum(1), (u2 * u2).sum(1), (u2 * r).sum(1)))
    v = np.maximum(0.0, t[None, :] - tb[:, None])
    v = np.where(t[None, :] <= tb[:, None] + p.post_s, v, 0.0)
    v2 = v * v
    sv, sv2, sv3, sv4, svr, sv2r = (x[None, :] for x in (v.sum(1), v2.sum(1), (v2 * v).sum(1), (v2 * v2).sum(1),
                                                         (v * r).sum(1), (v2 * r).sum(1)))
    g = np.zeros((ta.size, tb.size, 5, 5))
    h = np.zeros((ta.size, tb.size, 5))
    for i, j, val in ((0, 0, n), (0, 1, su2), (1, 1, su4), (0, 2, s_w), (2, 2, s_ww), (0, 3, sv), (2, 3, dq * sv),
                      (3, 3, sv2), (0, 4, sv2), (2, 4, dq * sv2), (3, 4, sv3), (4, 4, sv4)):
        g[..., i, j] = val
        g[..., j, i] = val
    for i, val in enumerate((s_r, su2r, s_wr, svr, sv2r)):
        h[..., i] = val
    d = np.sqrt(np.maximum(np.einsum("...ii->...i", g), 1e-30))  # scale to unit diagonal: t^4 terms are tiny
    gs = g / (d[..., :, None] * d[..., None, :]) + 1e-9 * np.eye(5)
    beta = np.linalg.solve(gs, (h / d)[..., None])[..., 0] / d
    sse = s_rr - np.sum(beta * h, axis=-1)
    rise = beta[..., 1] * p.pre_s**2  # <= 0: the level P - rise is where the approach window starts
    fall = beta[..., 3] * p.post_s + beta[..., 4] * p.post_s**2
    scale = 1.0 + beta[..., 2]
    ok = (valid & (n > 7) & (beta[..., 1] <= 0) & (beta[..., 3] <= 0)
          & (rise <= np.minimum(-min_step, 0.25 * fall)) & (fall <= np.minimum(-min_step, 0.25 * rise))
          & (scale >= p.inertia_range[0]) & (scale <= p.inertia_range[1]))
    return np.where(ok, sse / np.maximum(n - 7, 1), np.inf), beta


def free_rotor_interval(t: FloatArray, speed: FloatArray, torque: Signal, t_cross: float, direction: float,
                        inertia_kgm2: float, noise_rpm: float = 0.0, params: LashParams | None = None) -> GapOpen:
    """Find the free-rotor interval of one torque reversal (see the module docstring).

    Parameters
    ----------
    t, speed
        Motor speed samples: times (s, shape (n,), increasing) and rpm, covering at least
        ``t_cross - 0.08`` to ``t_cross + 0.28`` s.
    torque
        Motor torque (N m), aligned in time with the speed (shifted by the torque-to-speed offset).
    t_cross
        Torque zero-crossing time (s), on the speed's time base.
    direction
        +1 tip-in, -1 tip-out.
    inertia_kgm2
        Motor-referred inertia that moves with the rotor while the gaps are open (rotor and
        reducer gears, upstream of the half-shaft gap), kg m^2.
    noise_rpm
        White-noise RMS of the speed; the rise and the fall must each exceed 5x it.
    """
    p = params or LashParams()
    lo_t = t_cross + p.open_search_s[0] - p.pre_s
    hi_t = t_cross + p.close_search_s[1] + p.post_s
    m = (t >= lo_t) & (t <= hi_t) & np.isfinite(speed)
    if m.sum() < 10 or not inertia_kgm2 > 0:
        return NO_GAP
    t, speed = t[m], speed[m]
    q = direction * RPM_PER_RAD_S / inertia_kgm2 * _torque_integral(t, torque)
    if not np.isfinite(q).all():
        return NO_GAP
    r = direction * speed - q
    dt = float(np.median(np.diff(t)))
    min_step = max(p.min_step_rpm, 5.0 * noise_rpm)
    step = max(dt, 0.002)
    ta = np.arange(t_cross + p.open_search_s[0], t_cross + p.open_search_s[1], step)
    tb = np.arange(t_cross + p.close_search_s[0], t_cross + p.close_search_s[1], step)
    cost, _ = _fit_grid(t, r, q, ta, tb, p, min_step)
    if not np.isfinite(cost).any():
        return NO_GAP
    i, j = np.unravel_index(int(np.argmin(cost)), cost.shape)
    fine = min(dt / 4.0, 2.5e-4)
    ta2 = np.arange(ta[i] - step, ta[i] + step + fine / 2, fine)
    tb2 = np.arange(tb[j] - step, tb[j] + step + fine / 2, fine)
    cost2, beta = _fit_grid(t, r, q, ta2, tb2, p, min_step)
    if not np.isfinite(cost2).any():
        return NO_GAP
    i, j = np.unravel_index(int(np.argmin(cost2)), cost2.shape)
    return GapOpen(float(ta2[i]), float(tb2[j]), inertia_kgm2 / (1.0 + float(beta[i, j, 2])),
                   float(np.sqrt(cost2[i, j])))
