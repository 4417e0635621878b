"""Downsampling for plotting: at most ``max_points`` rows of a multi-column series, peaks kept.

Two methods, both choosing *rows* (every column at the same kept times):

``minmax``
    The rows are cut into equal buckets; in each bucket the rows holding each column's
    minimum and maximum are kept (plus the first and last row). No peak or valley of any
    column is ever lost -- the default for shuffle ripple.
``lttb``
    Largest-Triangle-Three-Buckets (Steinarsson 2013): one row per bucket, the one forming the
    largest triangle with the row kept in the previous bucket and the mean of the next bucket.
    With several columns the areas are added, each divided by its column's range. Visually
    faithful with half the points of ``minmax``, but a narrow extreme can be dropped.

``minmax`` reduces reshaped views with numpy's argmax/argmin; ``lttb`` is a compiled loop
(numba, ``nogil``: requests in other threads run meanwhile). NaN is ignored; memory-mapped
columns are read without a copy.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Literal

import numpy as np
import numpy.typing as npt
from numba import njit

from app.analysis.series import FloatArray
from app.errors import InputError

Method = Literal["minmax", "lttb"]
METHODS: tuple[str, ...] = ("minmax", "lttb")
IntArray = npt.NDArray[np.int64]


def _bucket_extremes(y: FloatArray, size: int, buckets: int, out: IntArray, col: int) -> None:
    """Rows of the max and the min of ``y`` in each bucket of ``size`` rows -> ``out[b, 2col:2col+2]``.

    Whole buckets are a reshaped view (no copy) reduced by numpy's SIMD argmax/argmin, which
    is about 3x faster than a compiled loop that tracks the index; the short last bucket and
    any bucket holding a NaN (argmax stops at the first NaN) are redone apart.
    """
    n = y.size
    full = n // size
    hi, lo = out[:, 2 * col], out[:, 2 * col + 1]
    if full:
        whole = y[:full * size].reshape(full, size)
        base = np.arange(full, dtype=np.int64) * size
        hi[:full] = base + np.argmax(whole, axis=1)
        lo[:full] = base + np.argmin(whole, axis=1)
    if buckets > full:
        hi[full] = full * size + int(np.argmax(y[full * size:]))
        lo[full] = full * size + int(np.argmin(y[full * size:]))
    for b in np.flatnonzero(np.isnan(y[hi]) | np.isnan(y[lo])):
        seg = y[b * size:(b + 1) * size]
        ok = np.flatnonzero(~np.isnan(seg))
        if ok.size:
            hi[b] = b * size + ok[np.argmax(seg[ok])]
            lo[b] = b * size + ok[np.argmin(seg[ok])]


@njit(cache=True, nogil=True)
def _lttb(t: FloatArray, ys: FloatArray, scale: FloatArray, n_out: int) -> IntArray:  # pragma: no cover - compiled
    """LTTB rows for ``ys`` (k, n) sharing times ``t`` (n,); areas weighted by ``1 / scale`` (k,)."""
    n = t.size
    k = ys.shape[0]
    rows = np.empty(n_out, np.int64)
    rows[0] = 0
    rows[n_out - 1] = n - 1
    every = (n - 2) / (n_out - 2)
    a = 0
    avg = np.empty(k)
    for i in range(n_out - 2):
        s = int(np.floor(i * every)) + 1
        e = int(np.floor((i + 1) * every)) + 1
        ns = e
        ne = min(int(np.floor((i + 2) * every)) + 1, n)
        t_avg = 0.0
        for j in range(ns, ne):
            t_avg += t[j]
        t_avg /= max(ne - ns, 1)
        for c in range(k):
            acc = 0.0
            cnt = 0
            for j in range(ns, ne):
                v = ys[c, j]
                if v == v:
                    acc += v
                    cnt += 1
            avg[c] = acc / cnt if cnt else np.nan
        best = -1.0
        pick = s
        for j in range(s, e):
            area = 0.0
            for c in range(k):
                ya, yj, ym = ys[c, a], ys[c, j], avg[c]
                if ya == ya and yj == yj and ym == ym:
                    area += abs((t[a] - t_avg) * (yj - ya) - (t[a] - t[j]) * (ym - ya)) / scale[c]
            if area > best:
                best = area
                pick = j
        rows[i + 1] = pick
        a = pick
    return rows


def _check(max_points: int, minimum: int, columns: int) -> None:
    if max_points < minimum:
        raise InputError(f"max_points = {max_points}: must be at least {minimum} for {columns} series")


def minmax_rows(columns: list[FloatArray], max_points: int) -> IntArray:
    """Row indices (increasing) keeping every bucket's min and max of every column, first and last row."""
    n = columns[0].size
    per_bucket = 2 * max(1, len(columns))
    _check(max_points, 2 + per_bucket, len(columns))
    if n <= max_points:
        return np.arange(n, dtype=np.int64)
    buckets = max(1, (max_points - 2) // per_bucket)
    size = int(np.ceil(n / buckets))
    buckets = int(np.ceil(n / size))
    picks = np.empty((buckets, per_bucket), np.int64)
    for c, y in enumerate(columns):
        _bucket_extremes(np.asarray(y, dtype=np.float64), size, buckets, picks, c)
    picks.sort(axis=1)  # buckets are disjoint and in order: sorting within each gives a sorted whole
    flat = np.concatenate(([0], picks.ravel(), [n - 1]))
    return flat[np.concatenate(([True], np.diff(flat) > 0))]


class BlockExtremes:
    """Each column's max and min row per block of ``block`` rows, built once for a long stored series.

    A min/max read of a long window then reduces ``n / block`` block extremes instead of ``n``
    rows: buckets are whole multiples of the block (edges at fixed multiples of the bucket
    size), only the two partial end buckets of the window are scanned row by row. The rows kept
    have the same property as :func:`minmax_rows` -- every bucket's min and max of every column,
    the window's first and last row -- with slightly different bucket edges.
    """

    def __init__(self, columns: list[FloatArray], block: int = 64) -> None:
        self.block = block
        self.n = columns[0].size
        nblocks = -(-self.n // block)
        self._rows = np.empty((nblocks, 2 * len(columns)), np.int64)
        for c, y in enumerate(columns):
            _bucket_extremes(np.asarray(y, dtype=np.float64), block, nblocks, self._rows, c)
        self._vals = np.empty(self._rows.shape)
        for c, y in enumerate(columns):
            hi, lo = y[self._rows[:, 2 * c]], y[self._rows[:, 2 * c + 1]]
            self._vals[:, 2 * c] = np.where(np.isnan(hi), -np.inf, hi)  # all-NaN blocks never win
            self._vals[:, 2 * c + 1] = np.where(np.isnan(lo), -np.inf, -lo)  # negated: argmax finds the min

    def rows(self, columns: list[FloatArray], lo: int, hi: int, max_points: int) -> IntArray:
        """Rows (increasing, in ``[lo, hi)``) of a min/max downsampling of ``columns[lo:hi]``."""
        k = len(columns)
        per_bucket = 2 * k
        _check(max_points, 2 + per_bucket, k)
        m = hi - lo
        buckets = max(1, (max_points - 2) // per_bucket)
        size = -(-m // buckets)
        if m <= max_points or size < 4 * self.block:
            return lo + minmax_rows([y[lo:hi] for y in columns], max_points)
        size = -(-size // self.block) * self.block
        while (hi - 1) // size - lo // size + 1 > buckets:  # fixed edges may add one partial bucket
            size += self.block
        k0, k1 = lo // size, (hi - 1) // size
        picks = [np.array([lo, hi - 1])]
        for a, b in ((lo, min(hi, (k0 + 1) * size)), (max(lo, k1 * size), hi)):  # the partial end buckets
            one = np.empty((1, per_bucket), np.int64)
            for c, y in enumerate(columns):
                _bucket_extremes(np.asarray(y[a:b], dtype=np.float64), b - a, 1, one, c)
            picks.append(a + one.ravel())
        if k1 - k0 > 1:  # whole buckets in between, from the block extremes
            per = size // self.block
            b0, b1 = (k0 + 1) * per, k1 * per
            vals = self._vals[b0:b1].reshape(k1 - k0 - 1, per, per_bucket)
            best = np.argmax(vals, axis=1)  # (buckets, 2k): the winning block of each extreme
            picks.append(self._rows[b0:b1].reshape(k1 - k0 - 1, per, per_bucket)[
                np.arange(k1 - k0 - 1)[:, None], best, np.arange(per_bucket)[None, :]].ravel())
        flat = np.sort(np.concatenate(picks))
        return flat[np.concatenate(([True], np.diff(flat) > 0))]


def lttb_rows(t: FloatArray, columns: list[FloatArray], max_points: int) -> IntArray:
    """Row indices (increasing) chosen by multi-column LTTB, ``max_points`` of them (all rows if fewer)."""
    _check(max_points, 3, len(columns))
    n = t.size
    if n <= max_points:
        return np.arange(n, dtype=np.int64)
    ys = np.vstack([np.asarray(y, dtype=np.float64) for y in columns])
    with np.errstate(invalid="ignore"):
        span = np.array([np.nanmax(y) - np.nanmin(y) if np.isfinite(y).any() else 1.0 for y in ys])
    scale = np.where(np.isfinite(span) & (span > 0), span, 1.0)
    return np.asarray(_lttb(np.ascontiguousarray(t, dtype=np.float64), ys, scale, max_points))


def downsample(t: FloatArray, columns: Mapping[str, FloatArray], max_points: int,
               method: Method = "minmax") -> tuple[FloatArray, dict[str, FloatArray]]:
    """At most ``max_points`` rows of ``t`` (s, (n,)) and ``columns`` (each (n,)) by ``method``."""
    cols = [np.asarray(y) for y in columns.values()]
    if method == "minmax":
        rows = minmax_rows(cols, max_points)
    elif method == "lttb":
        rows = lttb_rows(np.asarray(t), cols, max_points)
    else:
        raise InputError(f"method = {method!r}: use one of {', '.join(METHODS)}")
    return np.asarray(t)[rows], {name: y[rows] for name, y in zip(columns, cols, strict=True)}


def warm_up() -> None:
    """Load (or compile) the kernels now, so the first request does not pay for it."""
    t = np.arange(64.0)
    downsample(t, {"a": np.sin(t)}, 10)
    downsample(t, {"a": np.sin(t)}, 10, "lttb")
