"""Zero-phase Butterworth filtering for the short windows of the drivability criteria.

Designs are cached (every event of a log, and its simulation, uses the same few), and the filter runs in
one compiled call (:mod:`app.analysis.feel_kernels`): the arithmetic of ``scipy.signal.sosfilt``/``sosfiltfilt``
(odd extension at both ends, steady-state initial conditions) without their per-call overhead, which
dominates on windows of a few hundred samples.
"""

from __future__ import annotations

import functools

import numpy as np
import numpy.typing as npt
from scipy import signal as sps

from app.analysis.feel_kernels import cascade, filtfilt

FloatArray = npt.NDArray[np.float64]


@functools.lru_cache(maxsize=64)
def butter_sos(order: int, cutoff: float | tuple[float, float], btype: str, fs: float) -> tuple[FloatArray, FloatArray]:
    """A Butterworth design and its steady-state initial conditions, cached: every event of a log (and its
    simulation) uses the same few. Second-order sections, merged into one transfer function when that is
    well conditioned (every pole at least ``MERGE_MIN_DISTANCE`` from z = 1), which halves the filter calls."""
    sos = np.asarray(sps.butter(order, cutoff, btype=btype, fs=fs, output="sos"), dtype=np.float64)
    poles = np.concatenate([np.roots(sec[3:]) for sec in sos])
    if sos.shape[0] > 1 and float(np.min(np.abs(1.0 - poles))) >= MERGE_MIN_DISTANCE:
        b, a = sps.sos2tf(sos)
        sos = np.concatenate((b, a))[None, :] if b.size == 3 else _tf_row(b, a)
    return sos, np.asarray(sps.sosfilt_zi(sos) if sos.shape[1] == 6 else _tf_zi(sos), dtype=np.float64)


MERGE_MIN_DISTANCE = 0.2


def _tf_row(b: FloatArray, a: FloatArray) -> FloatArray:
    """A merged transfer function stored as one row ``[b..., a...]`` (length 2 (order + 1))."""
    return np.concatenate((b, a))[None, :]


def _tf_zi(row: FloatArray) -> FloatArray:
    n = row.shape[1] // 2
    return np.asarray(sps.lfilter_zi(row[0, :n], row[0, n:]), dtype=np.float64)[None, :]


def zero_phase(design: tuple[FloatArray, FloatArray], a: FloatArray) -> FloatArray:
    """Forward-backward filtering with odd extension at both ends (what ``scipy.signal.sosfiltfilt`` does,
    with the initial conditions from the cached design)."""
    sos, zi = design
    order = (sos.shape[1] // 2 - 1) * sos.shape[0]
    n = min(a.size - 1, 3 * (order + 1))
    if n < 1:
        return np.asarray(a, dtype=np.float64)
    return np.asarray(filtfilt(sos, zi, np.ascontiguousarray(a, dtype=np.float64), n), dtype=np.float64)


def sections(sos: FloatArray, zi: FloatArray, x: FloatArray) -> FloatArray:
    """``scipy.signal.sosfilt(sos, x, zi=zi * x[0])``, row by row (a second-order section, or one merged
    transfer function) in one compiled call."""
    return np.asarray(cascade(sos, zi, np.ascontiguousarray(x, dtype=np.float64)), dtype=np.float64)
