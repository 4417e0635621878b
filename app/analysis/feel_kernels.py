r"""Compiled inner loops of the drivability criteria (numba, on-disk cache): the IIR filter cascade and the
damped-sine least-squares fit.

An analysis computes the criteria of every event twice (measured and simulated), on windows of a few hundred
samples, where the per-call overhead of ``scipy.signal.lfilter`` and ``scipy.optimize.leastsq`` outweighs the
arithmetic. Both are done here in one compiled call each, with the same arithmetic:

* :func:`cascade` runs filter rows (second-order sections or one merged transfer function, stored
  ``[b..., a...]``) in transposed direct form II, the recurrence of ``lfilter``, each starting from its
  steady state for the first input sample (``zi * x[0]``, as ``sosfilt`` with ``sosfilt_zi``);
  :func:`filtfilt` adds the odd extension and the backward pass of ``sosfiltfilt``.
* :func:`damped_sine_fit` minimises ``sum (c + A exp(-sigma tau) cos(omega tau + phi) - y)^2`` by
  Levenberg-Marquardt (Marquardt's scaling by the diagonal of ``J^T J``, the damping lowered after a
  successful step and raised after a failed one) with the analytic Jacobian, to a relative step below
  ``1e-10`` -- tighter than the ``1e-6`` the MINPACK call it replaces stopped at, so it lands on the same
  minimum more exactly -- and returns ``(J^T J)^-1`` at the minimum for the parameters' standard errors.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

from app.analysis.series import FloatArray

FIT_OK, FIT_SINGULAR, FIT_NO_CONVERGENCE = 0, 1, 2
MAX_ITER = 200
XTOL = 1e-10  # converged: the step is below this fraction of the parameter vector's norm ...
FTOL = 1e-14  # ... or it lowers the sum of squares by less than this fraction


@njit(cache=True, nogil=True)
def cascade(rows: FloatArray, zi: FloatArray, x: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """``x`` through each row of ``rows`` in turn (shape (k, 2 (m + 1)): ``b`` then ``a``, ``a[0] = 1``),
    row ``r`` starting from the state ``zi[r] * x[0]`` (shape (k, m))."""
    n = x.size
    half = rows.shape[1] // 2
    m = half - 1
    y = x.copy()
    x0 = x[0]
    z = np.empty(m)
    b = np.empty(half)
    a = np.empty(half)
    for r in range(rows.shape[0]):
        for i in range(half):
            b[i] = rows[r, i] / rows[r, half]
            a[i] = rows[r, half + i] / rows[r, half]
        for i in range(m):
            z[i] = zi[r, i] * x0
        for k in range(n):
            xi = y[k]
            yi = z[0] + b[0] * xi
            for i in range(m - 1):
                z[i] = z[i + 1] + xi * b[i + 1] - yi * a[i + 1]
            z[m - 1] = xi * b[m] - yi * a[m]
            y[k] = yi
    return y


@njit(cache=True, nogil=True)
def filtfilt(rows: FloatArray, zi: FloatArray, a: FloatArray, pad: int) -> FloatArray:  # pragma: no cover
    """Forward-backward :func:`cascade` over ``a`` extended by ``pad`` samples of odd reflection at each end
    (``1 <= pad <= a.size - 1``), the extension cut off again: ``sosfiltfilt``'s arithmetic."""
    n = a.size
    ext = np.empty(n + 2 * pad)
    for i in range(pad):
        ext[i] = 2.0 * a[0] - a[pad - i]
        ext[n + pad + i] = 2.0 * a[n - 1] - a[n - 2 - i]
    ext[pad:pad + n] = a
    y = cascade(rows, zi, ext)
    y = cascade(rows, zi, y[::-1].copy())
    return y[::-1][pad:pad + n].copy()


@njit(cache=True, nogil=True)
def _residual(x: FloatArray, tau: FloatArray, y: FloatArray, r: FloatArray, ec: FloatArray,
              es: FloatArray) -> float:  # pragma: no cover - compiled
    """Residuals into ``r`` (and ``exp(-sig tau) cos``, ``sin`` into ``ec``, ``es``); their sum of squares
    (inf when not finite)."""
    c, amp, sig, w, phi = x[0], x[1], x[2], x[3], x[4]
    s = 0.0
    for k in range(tau.size):
        e = math.exp(-sig * tau[k])
        ph = w * tau[k] + phi
        ec[k] = e * math.cos(ph)
        es[k] = e * math.sin(ph)
        r[k] = c + amp * ec[k] - y[k]
        s += r[k] * r[k]
    return s if math.isfinite(s) else math.inf


@njit(cache=True, nogil=True)
def _normal(x: FloatArray, tau: FloatArray, r: FloatArray, ec: FloatArray, es: FloatArray, jtj: FloatArray,
            g: FloatArray) -> None:  # pragma: no cover - compiled
    """``J^T J`` and ``J^T r`` of the analytic Jacobian at ``x`` (columns d/dc, d/dA, d/dsig, d/dw, d/dphi)."""
    amp = x[1]
    jtj[:, :] = 0.0
    g[:] = 0.0
    row = np.empty(5)
    for k in range(tau.size):
        row[0] = 1.0
        row[1] = ec[k]
        row[2] = -amp * tau[k] * ec[k]
        row[3] = -amp * tau[k] * es[k]
        row[4] = -amp * es[k]
        for i in range(5):
            g[i] += row[i] * r[k]
            for j in range(i + 1):
                jtj[i, j] += row[i] * row[j]
    for i in range(5):
        for j in range(i + 1, 5):
            jtj[i, j] = jtj[j, i]


@njit(cache=True, nogil=True)
def _solve(a: FloatArray, b: FloatArray, out: FloatArray) -> bool:  # pragma: no cover - compiled
    """``out = a^-1 b`` for a symmetric positive definite 5 x 5 ``a`` (Cholesky); False when it is not."""
    n = 5
    lo = np.zeros((n, n))
    for i in range(n):
        for j in range(i + 1):
            s = a[i, j]
            for k in range(j):
                s -= lo[i, k] * lo[j, k]
            if i == j:
                if not s > 0.0:
                    return False
                lo[i, i] = math.sqrt(s)
            else:
                lo[i, j] = s / lo[j, j]
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= lo[i, k] * out[k]
        out[i] = s / lo[i, i]
    for i in range(n - 1, -1, -1):
        s = out[i]
        for k in range(i + 1, n):
            s -= lo[k, i] * out[k]
        out[i] = s / lo[i, i]
    return True


@njit(cache=True, nogil=True)
def damped_sine_fit(tau: FloatArray, y: FloatArray, x0: FloatArray) -> tuple[int, FloatArray, float, float]:
    """Least-squares ``c, A, sigma, omega, phi`` of ``c + A exp(-sigma tau) cos(omega tau + phi)`` to ``y``
    from the start ``x0`` (module docstring). Returns (status, parameters, sum of squares, ``(J^T J)^-1``
    at [1, 1]: the amplitude's variance per unit residual variance)."""  # pragma: no cover - compiled
    n = tau.size
    x = x0.copy()
    r, ec, es = np.empty(n), np.empty(n), np.empty(n)
    rt, ect, est = np.empty(n), np.empty(n), np.empty(n)
    jtj, g = np.empty((5, 5)), np.empty(5)
    aug, step, trial, rhs = np.empty((5, 5)), np.empty(5), np.empty(5), np.empty(5)
    cost = _residual(x, tau, y, r, ec, es)
    if not math.isfinite(cost):
        return FIT_NO_CONVERGENCE, x, cost, math.inf
    lam = 1e-3
    status = FIT_NO_CONVERGENCE
    for _ in range(MAX_ITER):
        _normal(x, tau, r, ec, es, jtj, g)
        for i in range(5):
            rhs[i] = -g[i]
        accepted = False
        while lam <= 1e16:
            aug[:, :] = jtj
            for i in range(5):
                aug[i, i] = jtj[i, i] * (1.0 + lam)
            if _solve(aug, rhs, step):
                for i in range(5):
                    trial[i] = x[i] + step[i]
                c_new = _residual(trial, tau, y, rt, ect, est)
                if c_new <= cost:
                    accepted = True
                    break
            lam *= 10.0
        if not accepted:
            status = FIT_OK  # no step lowers the sum of squares: a minimum to the arithmetic's precision
            break
        lam = max(lam * 0.1, 1e-15)
        nx = 0.0
        ns = 0.0
        for i in range(5):
            nx += trial[i] * trial[i]
            ns += step[i] * step[i]
        small = math.sqrt(ns) <= XTOL * math.sqrt(nx) or cost - c_new <= FTOL * cost
        x[:] = trial
        r[:] = rt
        ec[:] = ect
        es[:] = est
        cost = c_new
        if small:
            status = FIT_OK
            break
    if status != FIT_OK:
        return status, x, cost, math.inf
    _normal(x, tau, r, ec, es, jtj, g)
    e1 = np.zeros(5)
    e1[1] = 1.0
    if not _solve(jtj, e1, step):
        return FIT_SINGULAR, x, cost, math.inf
    return FIT_OK, x, cost, step[1]


@njit(cache=True, nogil=True)
def median(x: FloatArray) -> float:  # pragma: no cover - compiled
    """``np.median`` of a non-empty finite ``x`` (the middle value, or the mean of the two middle ones)."""
    s = np.sort(x)
    h = s.size // 2
    return float(s[h]) if s.size % 2 else (s[h - 1] + s[h]) / 2.0


@njit(cache=True, nogil=True)
def zigzag(seg: FloatArray, prominence: float) -> npt.NDArray[np.int64]:  # pragma: no cover - compiled
    """Indices of the alternating extrema of ``seg`` (a maximum first), each at least ``prominence`` away from
    the one before: :func:`app.analysis.drivability._extrema` on the segment from its start."""
    n = seg.size
    out = np.empty(n + 1, dtype=np.int64)
    kinds = np.empty(n + 1)
    first_max = -1
    for i in range(1, n - 1):
        if seg[i] - seg[i - 1] > 0 and seg[i + 1] - seg[i] <= 0:
            first_max = i
            break
    start = 0
    if first_max >= 0:  # the lowest sample up to the first local maximum stands for the preceding minimum
        for i in range(1, first_max + 1):
            if seg[i] < seg[start]:
                start = i
    out[0] = start
    kinds[0] = -1.0
    m = 1
    for k in range(1, n - 1):
        d0 = seg[k] - seg[k - 1]
        d1 = seg[k + 1] - seg[k]
        if d0 > 0 and d1 <= 0:
            kind = 1.0
        elif d0 < 0 and d1 >= 0:
            kind = -1.0
        else:
            continue
        last = out[m - 1]
        if k <= last:
            continue
        if kind == kinds[m - 1]:
            if kind * seg[k] > kind * seg[last]:
                out[m - 1] = k
        elif abs(seg[k] - seg[last]) >= prominence:
            out[m] = k
            kinds[m] = kind
            m += 1
    return out[1:m].copy()


@njit(cache=True, nogil=True)
def fourth_power_dose(rows: FloatArray, zi: FloatArray, a: FloatArray, fs: float) -> float:  # pragma: no cover
    """``(sum w^4 / fs)^(1/4)`` of ``w``, ``a`` through :func:`cascade` (the vibration dose value of a
    frequency-weighted acceleration)."""
    w = cascade(rows, zi, a)
    s = 0.0
    for k in range(w.size):
        v = w[k] * w[k]
        s += v * v
    return (s / fs) ** 0.25


@njit(cache=True, nogil=True)
def max_abs_slope(y: FloatArray, dt: float, k0: int, k1: int) -> float:  # pragma: no cover - compiled
    """``max |np.gradient(y, dt)[k0:k1]|`` (central differences inside ``y``, one-sided at its ends) for
    ``0 <= k0 < k1 <= y.size``, ``y.size >= 2``."""
    n = y.size
    best = -1.0
    for k in range(k0, k1):
        if k == 0:
            g = (y[1] - y[0]) / dt
        elif k == n - 1:
            g = (y[n - 1] - y[n - 2]) / dt
        else:
            g = (y[k + 1] - y[k - 1]) / (2.0 * dt)
        if abs(g) > best:
            best = abs(g)
    return best


@njit(cache=True, nogil=True)
def sinc_refine(y: FloatArray, idx: npt.NDArray[np.int64], weights: FloatArray,
                offsets: FloatArray) -> tuple[FloatArray, FloatArray]:  # pragma: no cover - compiled
    """Offset (samples) and value of the extremum near each ``y[idx[j]]`` (``8 <= idx[j] <= y.size - 9``) on the
    interpolation ``sum_k weights[r, k] y[i - 8 + k]`` at ``offsets[r]``: the largest value for a maximum, the
    smallest for a minimum (as ``y[i]`` against the mean of its neighbours says); the first of equal ones."""
    m = idx.size
    off = np.empty(m)
    val = np.empty(m)
    taps = weights.shape[1]
    half = taps // 2
    for j in range(m):
        i = idx[j]
        sign = 1.0 if y[i] >= 0.5 * (y[i - 1] + y[i + 1]) else -1.0
        best = -math.inf
        for r in range(weights.shape[0]):
            v = 0.0
            for k in range(taps):
                v += weights[r, k] * y[i - half + k]
            if sign * v > best:
                best = sign * v
                off[j] = offsets[r]
                val[j] = v
    return off, val


@njit(cache=True, nogil=True)
def residual_rms(a: FloatArray, b: FloatArray) -> float:  # pragma: no cover - compiled
    """``np.std(a - b)`` (the mean removed, divided by n)."""
    n = a.size
    s = 0.0
    for k in range(n):
        s += a[k] - b[k]
    mean = s / n
    q = 0.0
    for k in range(n):
        d = a[k] - b[k] - mean
        q += d * d
    return math.sqrt(q / n)
