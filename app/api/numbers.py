"""JSON arrays of floats with fixed decimals, written by a compiled loop.

Series responses carry thousands of numbers; Python's float formatting (``"%.3f" % x``, or
``json.dumps``) costs a few hundred ns each, which under 20 concurrent dashboard clients was
the largest share of a request. Here each number is rounded to an integer of
``10**decimals`` units and its digits written straight into a byte buffer (numba, ``nogil``,
so requests in other threads run meanwhile). NaN and inf become ``null``. A value too large
for the integer path (``|x| * 10**decimals >= 2**62``) falls back to Python formatting.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

FloatArray = npt.NDArray[np.float64]
_LIMIT = float(2**62)


@njit(cache=True, nogil=True)
def _format(a: FloatArray, decimals: int, out: npt.NDArray[np.uint8]) -> int:  # pragma: no cover - compiled
    """Write ``[x0,x1,...]`` into ``out``; returns the length, or -1 if a value is out of range."""
    scale = 10.0**decimals
    unit = 1
    for _ in range(decimals):
        unit *= 10
    pos = 0
    out[pos] = 91  # [
    pos += 1
    digits = np.empty(24, np.uint8)
    for i in range(a.size):
        if i:
            out[pos] = 44  # ,
            pos += 1
        x = a[i]
        if not np.isfinite(x):
            out[pos] = 110  # null
            out[pos + 1] = 117
            out[pos + 2] = 108
            out[pos + 3] = 108
            pos += 4
            continue
        m = abs(x) * scale
        if m >= _LIMIT:
            return -1
        q = np.int64(np.rint(m))
        if x < 0 and q != 0:
            out[pos] = 45  # -
            pos += 1
        ip = q // unit
        fp = q - ip * unit
        nd = 0
        while True:
            digits[nd] = 48 + ip % 10
            nd += 1
            ip //= 10
            if ip == 0:
                break
        for j in range(nd - 1, -1, -1):
            out[pos] = digits[j]
            pos += 1
        if decimals:
            out[pos] = 46  # .
            pos += 1
            for j in range(decimals - 1, -1, -1):
                out[pos + j] = 48 + fp % 10
                fp //= 10
            pos += decimals
    out[pos] = 93  # ]
    return pos + 1


def json_numbers(a: FloatArray, decimals: int) -> bytes:
    """``a`` (1-D) as a JSON array with ``decimals`` fixed decimals, ``null`` for NaN/inf."""
    arr = np.ascontiguousarray(a, dtype=np.float64)
    out = np.empty(2 + arr.size * (22 + decimals), np.uint8)
    n = _format(arr, decimals, out)
    if n >= 0:
        return out[:n].tobytes()
    finite = np.isfinite(arr)
    body = ",".join(f"{v:.{decimals}f}" if ok else "null" for v, ok in zip(arr.tolist(), finite.tolist(), strict=True))
    return f"[{body}]".encode()


def warm_up() -> None:
    """Load (or compile) the kernel now, so the first request does not pay for it."""
    json_numbers(np.array([1.5, np.nan, -2.25]), 3)
