"""Compiled residuals of one event at every candidate time offset, for :func:`~.forward.best_offset`.

The offset profile of a pass interpolates each event's simulated speed at ``offsets x samples``
shifted times. numpy builds the shifted times as a ``(k, n)`` array, searches each one in the
simulated grid, interpolates and subtracts, each step a new ``(k, n)`` array; this kernel does the
same arithmetic in one walk per offset with a moving cursor, straight into the caller's buffer.
It is ``np.interp``'s own arithmetic -- the same bracket, the same slope
``(fp[j+1] - fp[j]) / (xp[j+1] - xp[j])`` (computed once per interval, as numpy does when the grid
is no longer than the query), ``slope * (x - xp[j]) + fp[j]``, ``fp[j]`` on an exact grid hit, the
end values outside, numpy's fallbacks for a nan -- so every residual is bit for bit the one numpy
gives, and the sums that follow (numpy's, unchanged) are too.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]


@njit(cache=True, nogil=True)
def shifted_residuals(speed_t: FloatArray, meas: FloatArray, xp: FloatArray, fp: FloatArray, offsets: FloatArray,
                      r: FloatArray) -> None:
    """``r[q] = meas - np.interp(speed_t - offsets[q], xp, fp)`` for every offset (``r``: ``(k, n)``; ``xp``
    strictly increasing, at least one point)."""
    n = speed_t.size
    m = xp.size
    slopes = np.empty(max(m - 1, 0))
    for jj in range(m - 1):
        slopes[jj] = (fp[jj + 1] - fp[jj]) / (xp[jj + 1] - xp[jj])
    j_first = 0  # the cursor at the first sample, where the next offset's walk starts
    for q in range(offsets.size):
        off = offsets[q]
        j = j_first
        for i in range(n):
            # written out here: a helper returning the cursor is not inlined and costs several times this
            x = speed_t[i] - off
            if math.isnan(x):
                y = x
            elif x < xp[0]:
                y = fp[0]
                j = 0
            elif x >= xp[m - 1]:
                y = fp[m - 1]
            else:
                while j > 0 and xp[j] > x:
                    j -= 1
                while xp[j + 1] <= x:
                    j += 1
                if xp[j] == x:
                    y = fp[j]
                else:
                    slope = slopes[j]
                    y = slope * (x - xp[j]) + fp[j]
                    if math.isnan(y):
                        y = slope * (x - xp[j + 1]) + fp[j + 1]
                        if math.isnan(y) and fp[j] == fp[j + 1]:
                            y = fp[j]
            r[q, i] = meas[i] - y
            if i == 0:
                j_first = j
