"""Model-free estimate of the first torsional mode (shuffle) from a vehicle's own event windows.

The shuffle is seen in the motor speed after each torque reversal, once the lash has closed: the
driveline is then linear and the speed is a rigid-body ramp plus a decaying oscillation that the
torque drives. This module estimates that mode's frequency and damping ratio per event window and
pools them over windows and logs, without any driveline model.

Why a parametric estimator: a window holds one to six shuffle periods (1 s after the crossing, a
2.5-15 Hz mode), and a CAN speed channel is often sampled at 20-50 Hz. A spectrum of so short a
record has a resolution of about 1 Hz and its peak is pulled by the ramp and the window; the
half-power width says nothing about a damping ratio at that length. A low-order discrete model
fitted in the time domain has no resolution limit and uses the torque that drove the response.

Per window (:func:`window_mode`):

1. **Re-time** both channels (:func:`~app.analysis.diagnosis.retime.retime_bursts`: frames a
   buffering logger wrote back-to-back get their sampling times back), then put the speed on a
   uniform grid at its nominal period (linear interpolation of the re-timed samples) and the
   torque on the same grid. Fast channels are decimated to at most ``MAX_RATE_HZ`` after a
   zero-phase low-pass applied to speed *and* torque alike, so the pair still obeys the same
   transfer function; 20-50 Hz channels are kept as they are.
2. **Lash closed**: the samples from the first one after ``t_cross`` where the torque has left the
   ``+-band_nm`` band on the event's side, to the first one where it comes back (or the window end).
3. **Model** of the speed increments ``dy_k = y_k - y_(k-1)`` (the difference cancels the rigid-body
   integrator; a road load becomes a constant)::

       A(q) dy_k = B(q) u_k + c,   A = 1 + a_1 q^-1 + ... + a_na q^-na,   B = b_0 + ... + b_(nb-1) q^-(nb-1)

   started from free initial increments, summed back to a speed with a free level, and fitted to
   the *speed* samples in the output-error sense. Least-squares ARX on the increments would be
   biased (the difference makes the noise coloured, and equation-error fits pull poles towards the
   noise) -- the reason a 1 kHz channel with 0.5 rpm quantisation needs more than ARX. The fit is
   separable: for given ``a`` the simulated speed is linear in ``b``, ``c``, the initial increments
   and the level, so only ``a`` is searched (:func:`scipy.optimize.least_squares`, started from the
   ARX solution) and the rest solved by linear least squares (variable projection).
4. **Order** ``(na, nb)`` among ``ORDERS`` by the Bayesian information criterion of the speed fit.
5. **Mode**: the z-plane pole pair with ``0.5 Hz <= f <= 0.4 fs`` that carries most of the fitted
   increments' energy; ``s = ln(z) / T``, ``f = |s| / 2 pi``, ``zeta = -Re(s) / |s|``.
6. **Interval** by the delta method from the covariance of ``a`` (the Gauss-Newton covariance of
   the projected problem, residual variance from the fit). It takes the order as known and the
   measured torque as exact: on the tests' windows a nominal 90 % covers 55-80 %
   (``bench/modal.py``), 80-90 % when their torque carries no noise (0.3 N m of it, summed by the
   model into a random walk of the speed, is most of the gap); neither a Newey-West covariance
   nor averaging over the orders by their BIC weights changed that much. The pooled interval
   therefore does not rest on it (only the weights do).

A window that gives no mode yields a reason instead (too few samples, the torque never leaving the
band, the speed not following the torque, no oscillatory pole pair).

Pooling (:func:`pooled_mode`): a window whose frequency is further from the median than
``OUTLIER_MADS`` robust spreads and than ``OUTLIER_SHARE`` of the median is set aside (a wrong pole
pair, an event the linear model does not describe; the second bound keeps the noisy spread of five
windows from casting out sound ones); the rest are combined as a random-effects weighted mean (DerSimonian-Laird
between-window variance) with a Hartung-Knapp interval: Student t with ``n - 1`` degrees of freedom
on the weighted spread of the windows about the mean. The interval thus rests on how much the
windows disagree, not on the per-window intervals (which assume white residuals and a right
order). With four to ten windows a percentile bootstrap of a median covers too little; the t
interval on the between-window spread is calibrated for so few (``bench/modal.py``: 85-98 %
for a 90 % interval from five windows).
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import OrderedDict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy import optimize, signal, stats

from app.analysis.diagnosis.noise import sample_period
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.diagnosis.retime import retime_bursts
from app.analysis.events import Event
from app.errors import InputError, InsufficientDataError
from app.serial import Serial, rule
from app.signals import SignalSet

FloatArray = npt.NDArray[np.float64]
ComplexArray = npt.NDArray[np.complex128]

MAX_RATE_HZ = 100.0  # faster channels are decimated to at most this rate (modes of interest are < 20 Hz)
ORDERS: tuple[tuple[int, int], ...] = ((2, 2), (2, 3), (3, 2), (3, 3), (4, 3))  # (na, nb) candidates
F_MIN_HZ = 0.5  # plausible band of the first torsional mode: F_MIN_HZ .. F_MAX_SHARE x sampling rate
F_MAX_SHARE = 0.4
MAX_GAP_PERIODS = 3.5  # longer holes in the speed after the lash closed (three frames lost) reject the window
MIN_SAMPLES = 14  # samples after the lash has closed
MAX_GRID_SHARE = 3.0  # the uniform grid may have at most this many times the samples (the rest were lost)
MIN_R2 = 0.7  # the model must explain this share of the speed beyond a straight line (noise alone: up to about 0.5)
SAMPLES_PER_PARAM = 2.0  # an order is tried only with this many samples per parameter
MAX_EVALS = 100  # residual evaluations of one order's search (a stalled search keeps its best point)
WINDOW_LEVEL = 0.9  # confidence level of the per-window intervals
MEMO_WINDOWS = 4096  # window results kept (:func:`window_mode`): a staged identification meets its windows again
OUTLIER_MADS = 5.0  # pooled: a window further than this many robust spreads from the median ...
OUTLIER_SHARE = 0.1  # ... and than this share of it is set aside
METHOD = "output-error ARX on speed increments (variable projection), random-effects pooling"


@dataclass(frozen=True)
class EventWindow:
    """One event's measured samples; speed and torque may have different time bases.

    ``t_cross`` is the torque's zero crossing (s) and ``direction`` +1 for a tip-in (torque goes
    positive), -1 for a tip-out.
    """

    speed_t: FloatArray
    speed_rpm: FloatArray
    torque_t: FloatArray
    torque_nm: FloatArray
    t_cross: float
    direction: float


@dataclass(frozen=True)
class WindowMode:
    """The mode one event window gives: frequency (Hz), damping ratio and their ``WINDOW_LEVEL`` intervals.

    ``fs_hz`` is the rate the model was fitted at, ``n_samples`` the samples after the lash closed,
    ``order`` the model's ``(na, nb)`` and ``fit_r2`` the share of the speed beyond a straight line
    that the model explains.
    """

    t_event: float
    freq_hz: float
    zeta: float
    freq_ci: tuple[float, float]
    zeta_ci: tuple[float, float]
    fs_hz: float
    n_samples: int
    order: tuple[int, int]
    fit_r2: float


@dataclass(frozen=True)
class ModalEstimate(Serial):
    """The pooled mode over windows (and logs), with the windows used and the ones that gave none."""

    freq_hz: float
    freq_ci: tuple[float, float]
    zeta: float
    zeta_ci: tuple[float, float]
    n_windows: int  # windows offered (with or without a mode)
    n_used: int  # windows pooled
    windows: tuple[WindowMode, ...]  # the pooled ones
    rejected: tuple[tuple[float, str], ...] = field(metadata=rule(  # (t_event, reason)
        convert=lambda rs: [{"t_event": t, "reason": r} for t, r in rs]))
    method: str


@dataclass(frozen=True)
class _Fit:
    """One order's output-error fit of a window."""

    order: tuple[int, int]
    a: FloatArray  # denominator coefficients a_1..a_na
    cov_a: FloatArray  # their covariance
    fitted_dy: FloatArray  # the model's speed increments on the segment
    rss: float
    n_params: int


def _z(level: float) -> float:
    return float(stats.norm.ppf(0.5 + level / 2))


def _clean(t: npt.ArrayLike, v: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Finite samples with increasing times (a repeated stamp keeps its first sample)."""
    ta, va = np.asarray(t, dtype=np.float64).ravel(), np.asarray(v, dtype=np.float64).ravel()
    ok = np.isfinite(ta) & np.isfinite(va)
    ta, va = ta[ok], va[ok]
    order = np.argsort(ta, kind="stable")
    ta, va = ta[order], va[order]
    keep = np.r_[True, np.diff(ta) > 0][: ta.size]
    return ta[keep], va[keep]


def _retimed(t: FloatArray, period: float) -> FloatArray:
    """``t`` with buffered runs re-timed; the result is made increasing again (a run may overlap a neighbour)."""
    out, _ = retime_bursts(t, period)
    return np.maximum.accumulate(out)


def _sampling_clock(t: FloatArray, period: float) -> tuple[float, float]:
    """(phase, period) of the clock that sampled the re-timed stamps ``t``: a line through them against
    their frame numbers (drop-outs skip numbers).

    The median stamp difference is off by a fraction of a per cent when the stamps jitter to one
    side; a grid at that period drifts through the samples, and the changing interpolation offset
    damps a fast oscillation more and more along the window -- a damping ratio biased upwards.
    """
    for _ in range(2):
        k = np.round((t - t[0]) / period)
        period, start = (float(c) for c in np.polyfit(k, t, 1))
    return start + period * math.ceil((float(t[0]) - start) / period - 1e-9), period  # first tick on or after t[0]


@dataclass(frozen=True)
class _Grid:
    """A window on a uniform grid (``y`` speed, ``u`` torque, step ``dt``) and its re-timed torque samples."""

    t: FloatArray
    y: FloatArray
    u: FloatArray
    dt: float
    torque_t: FloatArray
    torque_nm: FloatArray
    speed_t: FloatArray  # re-timed speed stamps
    period: float  # their sampling period (s)


def _uniform(w: EventWindow, period_s: float | None) -> _Grid | str:
    """The window re-timed, on a uniform grid at the speed's period, decimated to at most ``MAX_RATE_HZ``."""
    for name, t, v in (("speed", w.speed_t, w.speed_rpm), ("torque", w.torque_t, w.torque_nm)):
        if np.size(t) != np.size(v):
            return f"{name} has {np.size(t)} times but {np.size(v)} values"
    st, sv = _clean(w.speed_t, w.speed_rpm)
    tt, tv = _clean(w.torque_t, w.torque_nm)
    if st.size < MIN_SAMPLES or tt.size < 3:
        return f"too few samples: {st.size} speed, {tt.size} torque"
    period = float(period_s) if period_s is not None else sample_period(st)
    if not (period > 0 and math.isfinite(period)):
        return f"speed sample period {period!r} s is not positive"
    span = float(st[-1] - st[0])
    if not (MIN_SAMPLES - 1) * period <= span <= MAX_GRID_SHARE * st.size * period:
        return f"a speed period of {period * 1000:.3g} ms does not fit {st.size} samples over {span:.3f} s"
    st = _retimed(st, period)
    tt = _retimed(tt, sample_period(tt))
    start, period = _sampling_clock(st, period)
    n = int(np.floor((st[-1] - start) / period)) + 1
    grid: FloatArray = start + period * np.arange(n, dtype=np.float64)
    y = np.interp(grid, st, sv)
    u = np.interp(grid, tt, tv)
    q = max(1, math.ceil(1.0 / (period * MAX_RATE_HZ) - 0.05))  # a 1.003 ms period still decimates by 5
    if q > 1:
        if n < 15 * q:
            return f"too few samples to decimate: {n} at {1 / period:.0f} Hz"
        sos = signal.butter(6, 0.8 / q, output="sos")  # 80 % of the new Nyquist frequency
        y = signal.sosfiltfilt(sos, y)[::q]
        u = signal.sosfiltfilt(sos, u)[::q]
        grid = grid[::q]
    return _Grid(grid, y, u, period * q, tt, tv, st, period)


def _lash_closed(tt: FloatArray, tv: FloatArray, w: EventWindow, grid: FloatArray, band_nm: float
                 ) -> tuple[int, int] | str:
    """Grid indices [i0, i1) during which the lash is closed after the crossing.

    The torque (re-timed samples ``tt``, ``tv``) is followed on the event's side from its largest
    value in its first excursion after the crossing (up to where it crosses zero again): back to
    the last sample still inside the ``+-band_nm`` band (the segment starts after it) and forward
    to the first one inside it again (a next reversal; the segment ends there), so a torque
    dithering on the band's edge during the ramp does not cut it.
    """
    side = math.copysign(1.0, w.direction) * tv
    after = np.flatnonzero(tt >= w.t_cross)
    out = after[side[after] > band_nm]
    if out.size == 0:
        return f"the torque does not leave the +-{band_nm:g} N m band after the crossing"
    back = np.flatnonzero(side[out[0]:] < 0.0)  # the torque crosses zero again: a later event
    first = after[0], out[0] + back[0] if back.size else tv.size
    peak = first[0] + int(np.argmax(side[first[0]:first[1]]))
    inside = side <= band_nm
    before = np.flatnonzero(inside[first[0]:peak])
    later = np.flatnonzero(inside[peak:])
    t0 = float(tt[first[0] + before[-1] + 1]) if before.size else float(tt[first[0]])
    t1 = float(tt[peak + later[0]]) if later.size else math.inf
    i0 = int(np.searchsorted(grid, t0))
    i1 = int(np.searchsorted(grid, t1))
    if i1 - i0 < MIN_SAMPLES:
        return f"too few samples after the lash closed: {max(i1 - i0, 0)} (need {MIN_SAMPLES})"
    return i0, i1


def _basis(a: FloatArray, u_lags: FloatArray, n: int) -> FloatArray:
    """Columns of the speed model for denominator ``a`` on ``n`` samples (see the module docstring).

    Increment columns (index 1..n-1): each input lag and the constant filtered by ``1/A``, and the
    free responses to a unit increment at each of the first ``na`` steps; summed to a speed with a
    zero start, plus the level column.
    """
    m = n - 1
    drive = np.zeros((m, u_lags.shape[1] + 1 + a.size))
    drive[:, :u_lags.shape[1]] = u_lags
    drive[:, u_lags.shape[1]] = 1.0
    drive[np.arange(a.size), u_lags.shape[1] + 1 + np.arange(a.size)] = 1.0
    dy = signal.lfilter([1.0], np.r_[1.0, a], drive, axis=0)
    speed = np.vstack([np.zeros((1, dy.shape[1])), np.cumsum(dy, axis=0)])
    return np.column_stack([speed, np.ones(n)])


def _project(a: FloatArray, u_lags: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray, int]:
    """(residual, linear parameters, rank) of the best speed fit for denominator ``a``.

    The columns are scaled to unit norm first: the torque lags are nearly collinear and their sums
    dwarf the level column, and a rank cut on the raw columns changed between neighbouring ``a``,
    which made the projected residual jump and its Jacobian (hence the interval) too small.
    """
    phi = _basis(a, u_lags, y.size)
    norm = np.linalg.norm(phi, axis=0)
    norm[norm == 0] = 1.0
    scaled, _, rank, _ = np.linalg.lstsq(phi / norm, y, rcond=None)
    theta = np.asarray(scaled / norm, dtype=np.float64)
    return y - phi @ theta, theta, int(rank)


def _arx_start(dy: FloatArray, u_lags: FloatArray, na: int) -> FloatArray:
    """Least-squares ARX denominator on the increments: the output-error search's starting point."""
    m = dy.size
    rows = np.arange(na, m)
    if rows.size <= na + u_lags.shape[1] + 1:
        return np.zeros(na)
    past = np.column_stack([-dy[rows - i] for i in range(1, na + 1)])
    x = np.column_stack([past, u_lags[rows], np.ones(rows.size)])
    coef, *_ = np.linalg.lstsq(x, dy[rows], rcond=None)
    return np.asarray(coef[:na], dtype=np.float64)


def _fit(y: FloatArray, u: FloatArray, i0: int, na: int, nb: int) -> _Fit | None:
    """Output-error fit of order (na, nb) to the speed ``y[i0:]`` driven by ``u`` (lags reach before i0)."""
    seg = y[i0:]
    n = seg.size
    idx = np.arange(i0 + 1, i0 + n)  # increment k of the segment is sample i0 + k
    u_lags = np.column_stack([u[np.clip(idx - j, 0, None)] for j in range(nb)])
    a0 = _arx_start(np.diff(seg), u_lags, na)
    roots = _roots(a0)
    if np.any(np.abs(roots) >= 1.0):  # start from a stable denominator
        roots = np.where(np.abs(roots) >= 1.0, 0.95 * roots / np.abs(roots), roots)
        a0 = np.real(np.poly(roots))[1:]
    try:
        sol = optimize.least_squares(lambda a: _project(a, u_lags, seg)[0], a0, method="lm", x_scale="jac",
                                     ftol=1e-6, xtol=1e-6, max_nfev=MAX_EVALS)
    except (ValueError, np.linalg.LinAlgError):
        return None
    if not np.all(np.isfinite(sol.x)):
        return None
    res, theta, rank = _project(sol.x, u_lags, seg)
    p = na + rank
    dof = n - p
    if dof <= 0:
        return None
    rss = float(res @ res)
    jac = np.asarray(sol.jac, dtype=np.float64)
    try:
        cov = np.linalg.inv(jac.T @ jac) * rss / dof
    except np.linalg.LinAlgError:
        return None
    fitted = np.diff(_basis(sol.x, u_lags, n) @ theta)
    return _Fit((na, nb), np.asarray(sol.x, dtype=np.float64), cov, fitted, rss, p)


def _roots(a: FloatArray) -> ComplexArray:
    """Poles of ``A(z) = z^na + a_1 z^(na-1) + ... + a_na``."""
    return np.roots(np.r_[1.0, a]).astype(np.complex128)


def _pole_mode(z: complex, dt: float) -> tuple[float, float]:
    """(frequency Hz, damping ratio) of a z-plane pole at sample period ``dt``."""
    s = np.log(complex(z)) / dt
    mag = abs(s)
    return float(mag / (2 * np.pi)), float(-s.real / mag)


def _pairs(a: FloatArray, dt: float) -> list[complex]:
    """Stable upper-half-plane poles of ``A`` whose frequency lies in the plausible band."""
    fmax = F_MAX_SHARE / dt
    out = []
    for z in _roots(a):
        if z.imag <= 1e-9 or abs(z) >= 1.0:
            continue
        f, _ = _pole_mode(z, dt)
        if F_MIN_HZ <= f <= fmax:
            out.append(complex(z))
    return out


def _energy(z: complex, poles: ComplexArray, dy: FloatArray) -> float:
    """Energy of pole pair ``z`` in the last two thirds of the increments ``dy`` (projected on all modes of
    the fit and a constant).

    The first third is left out: a heavily damped pair that only fits the start (the impact as the
    lash closes, a filter's transient) can carry more energy there than the shuffle does over the
    whole window.
    """
    k = np.arange(dy.size)
    cols = [np.ones(dy.size)]
    for p in poles:
        if p.imag < -1e-9:
            continue
        pk = np.power(complex(p), k)
        cols.extend([pk.real, pk.imag] if p.imag > 1e-9 else [pk.real])
    basis = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(basis, dy, rcond=1e-9)
    j = 1
    for p in poles:
        if p.imag < -1e-9:
            continue
        width = 2 if p.imag > 1e-9 else 1
        if abs(complex(p) - z) < 1e-12:
            part = basis[dy.size // 3:, j:j + width] @ coef[j:j + width]
            return float(part @ part)
        j += width
    return 0.0


def _strongest(fit: _Fit, dt: float) -> complex | None:
    """The in-band pole pair carrying most of the fitted increments' energy (:func:`_energy`); None without one."""
    pairs = _pairs(fit.a, dt)
    if not pairs:
        return None
    poles = _roots(fit.a)
    energies = [_energy(z, poles, fit.fitted_dy) for z in pairs]
    return pairs[int(np.argmax(energies))]


def _mode_and_cov(fit: _Fit, z: complex, dt: float) -> tuple[float, float, FloatArray]:
    """(f, zeta, their 2x2 covariance) of pole ``z`` by the delta method on the denominator covariance."""
    f0, zeta0 = _pole_mode(z, dt)
    grad = np.zeros((2, fit.a.size))
    for i in range(fit.a.size):
        h = 1e-6 * max(1.0, abs(float(fit.a[i])))
        a = fit.a.copy()
        a[i] += h
        roots = _roots(a)
        zi = roots[np.argmin(np.abs(roots - z))]
        f1, zeta1 = _pole_mode(complex(zi.real, abs(zi.imag)), dt)
        grad[:, i] = [(f1 - f0) / h, (zeta1 - zeta0) / h]
    return f0, zeta0, grad @ fit.cov_a @ grad.T


def _bic(fit: _Fit, n: int) -> float:
    return n * math.log(max(fit.rss, 1e-300) / n) + fit.n_params * math.log(n)


@dataclass(frozen=True)
class Segment:
    """A window on the uniform grid (``dt`` s), cut where the lash opens again; it is closed from ``start`` on.

    The samples before ``start`` are kept: the model's torque lags reach back into them.
    """

    speed_rpm: FloatArray
    torque_nm: FloatArray
    start: int
    dt: float


def lash_closed_segment(w: EventWindow, *, period_s: float | None = None, band_nm: float = 5.0) -> Segment | str:
    """The window re-timed, on a uniform grid and cut to where the lash is closed; or why that is not possible.

    Parameters as :func:`window_mode`'s.
    """
    on_grid = _uniform(w, period_s)
    if isinstance(on_grid, str):
        return on_grid
    span = _lash_closed(on_grid.torque_t, on_grid.torque_nm, w, on_grid.t, band_nm)
    if isinstance(span, str):
        return span
    i0, i1 = span
    st = on_grid.speed_t
    inside = st[(st >= on_grid.t[i0]) & (st <= on_grid.t[i1 - 1])]
    gap = float(np.diff(inside).max(initial=0.0))
    if gap > MAX_GAP_PERIODS * on_grid.period:
        return f"a gap of {gap * 1000:.0f} ms in the speed after the lash closed (frames lost)"
    return Segment(on_grid.y[:i1], on_grid.u[:i1], i0, on_grid.dt)


_MEMO: OrderedDict[bytes, WindowMode | str] = OrderedDict()
_MEMO_LOCK = threading.Lock()


def _window_key(w: EventWindow, period_s: float | None, band_nm: float) -> bytes:
    h = hashlib.blake2b(digest_size=20)
    for a in (w.speed_t, w.speed_rpm, w.torque_t, w.torque_nm):
        arr = np.ascontiguousarray(a, dtype=np.float64)
        h.update(arr.size.to_bytes(8, "little"))
        h.update(arr.tobytes())
    h.update(np.array([w.t_cross, w.direction, np.nan if period_s is None else period_s, band_nm]).tobytes())
    return h.digest()


def window_mode(w: EventWindow, *, period_s: float | None = None, band_nm: float = 5.0) -> WindowMode | str:
    """:func:`window_estimate`, kept for the window's samples and arguments: each stage of a sequential design
    (:func:`app.identify.fit.identify_staged`, the diagnosis') takes the previous stage's windows again, and the
    windows' output-error searches are a large share of a long drive's identification (16 of its 47 s under the
    profiler on a 30-minute drive, 48 of 144 searches repeats). The result is the same object each time (frozen, or a
    reason)."""
    key = _window_key(w, period_s, band_nm)
    with _MEMO_LOCK:
        hit = _MEMO.get(key)
        if hit is not None:
            _MEMO.move_to_end(key)
            return hit
    out = window_estimate(w, period_s=period_s, band_nm=band_nm)
    with _MEMO_LOCK:
        _MEMO[key] = out
        while len(_MEMO) > MEMO_WINDOWS:
            _MEMO.popitem(last=False)
    return out


def window_estimate(w: EventWindow, *, period_s: float | None = None, band_nm: float = 5.0) -> WindowMode | str:
    """The first torsional mode one event window shows, or the reason it shows none.

    Parameters
    ----------
    w : the window's samples, the torque crossing and the event's direction.
    period_s : the speed channel's nominal sample period (s); estimated from the window when None
        (pass the whole log's when known: a short window's stamps give a noisier estimate).
    band_nm : the torque band around zero in which the lash may be open (N m).
    """
    closed = lash_closed_segment(w, period_s=period_s, band_nm=band_nm)
    if isinstance(closed, str):
        return closed
    y, u, i0, dt = closed.speed_rpm, closed.torque_nm, closed.start, closed.dt
    seg = y[i0:]
    n = seg.size
    tn = np.arange(n, dtype=np.float64)
    line = seg - np.polyval(np.polyfit(tn, seg, 1), tn)
    beyond = float(line @ line)
    if float(np.ptp(seg)) <= 1e-9 * max(1.0, float(np.abs(seg).max())):
        return "the speed does not change after the lash closed"
    fits = [f for na, nb in ORDERS if n >= SAMPLES_PER_PARAM * (2 * na + nb + 2)
            for f in [_fit(y, u, i0, na, nb)] if f is not None]
    if not fits:
        return f"too few samples for any model order: {n}"
    best_r2 = max(1.0 - f.rss / beyond for f in fits)
    if best_r2 < MIN_R2:
        return f"the speed does not follow the torque: the model explains R2 {best_r2:.2f} beyond a line"
    fits = [f for f in fits if 1.0 - f.rss / beyond >= MIN_R2]
    candidates = [(_bic(f, n), f, z) for f in fits for z in [_strongest(f, dt)] if z is not None]
    if not candidates:
        return f"no oscillatory pole pair in {F_MIN_HZ:g}-{F_MAX_SHARE / dt:.1f} Hz"
    _, fit, z = min(candidates, key=lambda c: c[0])
    freq, zeta, cov = _mode_and_cov(fit, z, dt)
    zq = _z(WINDOW_LEVEL)
    sf, sz = math.sqrt(max(cov[0, 0], 0.0)), math.sqrt(max(cov[1, 1], 0.0))
    return WindowMode(
        t_event=float(w.t_cross), freq_hz=freq, zeta=zeta, freq_ci=(freq - zq * sf, freq + zq * sf),
        zeta_ci=(max(zeta - zq * sz, 0.0), zeta + zq * sz), fs_hz=1.0 / dt, n_samples=n, order=fit.order,
        fit_r2=1.0 - fit.rss / beyond)


def _window_se(mode: WindowMode) -> tuple[float, float]:
    """Standard errors of a window's frequency and damping ratio, from the upper halves of its intervals."""
    zq = _z(WINDOW_LEVEL)
    return (mode.freq_ci[1] - mode.freq_hz) / zq, (mode.zeta_ci[1] - mode.zeta) / zq


def _random_effects(x: FloatArray, se: FloatArray, level: float) -> tuple[float, tuple[float, float]]:
    """Random-effects weighted mean and its Hartung-Knapp interval (see the module docstring)."""
    if x.size == 1:
        half = _z(level) * float(se[0])
        return float(x[0]), (float(x[0]) - half, float(x[0]) + half)
    var = np.maximum(se, 1e-12) ** 2
    w = 1.0 / var
    mean_w = float(w @ x / w.sum())
    q = float(w @ (x - mean_w) ** 2)
    denom = float(w.sum() - (w @ w) / w.sum())
    tau2 = max(0.0, (q - (x.size - 1)) / denom) if denom > 0 else 0.0
    ws = 1.0 / (var + tau2)
    mean = float(ws @ x / ws.sum())
    v_hk = float(ws @ (x - mean) ** 2) / ((x.size - 1) * float(ws.sum()))
    half = float(stats.t.ppf(0.5 + level / 2, x.size - 1)) * math.sqrt(v_hk)
    return mean, (mean - half, mean + half)


def pooled_mode(windows: Sequence[WindowMode], level: float = 0.9,
                rejected: Sequence[tuple[float, str]] = ()) -> ModalEstimate:
    """The mode pooled over windows (of one log or several), with a ``level`` interval.

    Raises
    ------
    InsufficientDataError
        (code ``insufficient_data``) when no window gives a mode.
    InputError
        (code ``invalid_input``) for a level outside (0, 1).
    """
    if not 0.0 < level < 1.0:
        raise InputError(f"confidence level {level!r} must lie strictly between 0 and 1")
    out_rejected = list(rejected)
    kept = list(windows)
    if not kept and not out_rejected:
        raise InsufficientDataError("no event windows to estimate a torsional mode from (no torque reversal kept)")
    if not kept:
        reasons = "; ".join(sorted({r for _, r in out_rejected}))
        raise InsufficientDataError(f"none of the {len(out_rejected)} event windows gives a torsional mode: {reasons}")
    if len(kept) >= 4:
        f = np.array([m.freq_hz for m in kept])
        med = float(np.median(f))
        spread = 1.4826 * float(np.median(np.abs(f - med)))
        far = np.abs(f - med) > max(OUTLIER_MADS * spread, OUTLIER_SHARE * med)
        if far.any():
            out_rejected += [(m.t_event, f"outlier: {m.freq_hz:.2f} Hz against the median {med:.2f} Hz")
                             for m, bad in zip(kept, far, strict=True) if bad]
            kept = [m for m, bad in zip(kept, far, strict=True) if not bad]
    se = np.array([_window_se(m) for m in kept])
    freq, freq_ci = _random_effects(np.array([m.freq_hz for m in kept]), se[:, 0], level)
    zeta, zeta_ci = _random_effects(np.array([m.zeta for m in kept]), se[:, 1], level)
    return ModalEstimate(freq_hz=freq, freq_ci=freq_ci, zeta=zeta, zeta_ci=(max(zeta_ci[0], 0.0), zeta_ci[1]),
                         n_windows=len(windows) + len(rejected), n_used=len(kept), windows=tuple(kept),
                         rejected=tuple(out_rejected), method=METHOD)


def estimate_modes(event_windows: Iterable[EventWindow], level: float = 0.9) -> ModalEstimate:
    """Each window's mode (:func:`window_mode`) pooled (:func:`pooled_mode`); windows without one are listed."""
    modes: list[WindowMode] = []
    rejected: list[tuple[float, str]] = []
    for w in event_windows:
        m = window_mode(w)
        if isinstance(m, str):
            rejected.append((float(w.t_cross), m))
        else:
            modes.append(m)
    return pooled_mode(modes, level, rejected)


def modes_from_signals(signals: SignalSet, events: Sequence[Event], level: float = 0.9) -> ModalEstimate:
    """The pooled mode of a decoded log, from the windows the diagnosis cuts around the events it keeps.

    The windows are :func:`app.analysis.diagnosis.prepare.prepare`'s (re-timed channels, the event's
    window ``pre_s`` before to ``post_s`` after the crossing); events it leaves out are listed as
    rejected with its reason.
    """
    diag, noise, skipped = prepare(signals, events)
    reasons = {s["index"]: s["reason"] for s in skipped}
    rejected = [(ev.t_cross_s, str(reasons[ev.index])) for ev in events if ev.index in reasons]
    modes: list[WindowMode] = []
    for ev in diag:
        w = EventWindow(speed_t=ev.speed_t, speed_rpm=ev.speed_meas, torque_t=ev.torque_t, torque_nm=ev.torque_nm,
                        t_cross=ev.t_event, direction=1.0 if ev.kind == "tip_in" else -1.0)
        m = window_mode(w, period_s=noise.period_s, band_nm=DIAGNOSIS_EVENTS.hysteresis_nm)
        if isinstance(m, str):
            rejected.append((ev.t_event, m))
        else:
            modes.append(m)
    return pooled_mode(modes, level, rejected)
