"""Torque input checks: irregular sample times are fine, unusable input raises InputSignalError."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.errors import InputSignalError

F64 = NDArray[np.float64]
INTERP_MODES = ("hold", "linear")


@dataclass(frozen=True)
class TorqueInput:
    """Validated torque samples. ``gaps``: (t_start, t_end) spans longer than ``gap_factor`` x median step."""

    t: F64  # (n,) s, strictly increasing
    torque: F64  # (n,) N m
    linear: bool
    gaps: tuple[tuple[float, float], ...]


def prepare_input(
    t_s: ArrayLike, torque_nm: ArrayLike, interp: str = "hold", *, gap_factor: float = 5.0
) -> TorqueInput:
    """Check and convert torque samples.

    Parameters
    ----------
    t_s : (n,) sample times in s, strictly increasing, spacing may be irregular
    torque_nm : (n,) motor torque in N m (CAN request/estimate)
    interp : "hold" (previous sample, as a CAN value holds until the next frame) or "linear"

    Raises
    ------
    InputSignalError
        Empty or mismatched arrays, non-finite values, non-increasing time, unknown ``interp``.
    """
    if interp not in INTERP_MODES:
        raise InputSignalError(f"interp = {interp!r}: must be one of {INTERP_MODES}")
    t = np.asarray(t_s, dtype=np.float64).ravel()
    q = np.asarray(torque_nm, dtype=np.float64).ravel()
    if t.size == 0:
        raise InputSignalError("t_s is empty: need at least two torque samples")
    if t.size != q.size:
        raise InputSignalError(f"t_s has {t.size} samples but torque_nm has {q.size}")
    if t.size < 2:
        raise InputSignalError("need at least two torque samples to span a time interval")
    bad_t = np.flatnonzero(~np.isfinite(t))
    if bad_t.size:
        raise InputSignalError(f"t_s[{bad_t[0]}] = {float(t[bad_t[0]])!r}: sample times must be finite")
    bad_q = np.flatnonzero(~np.isfinite(q))
    if bad_q.size:
        raise InputSignalError(f"torque_nm[{bad_q[0]}] = {float(q[bad_q[0]])!r} at t = {t[bad_q[0]]:.6f} s: "
                               "must be finite")
    step = np.diff(t)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = int(bad[0])
        raise InputSignalError(f"t_s[{k + 1}] = {float(t[k + 1])!r} <= t_s[{k}] = {float(t[k])!r}: "
                               "times must strictly increase")
    med = float(np.median(step))
    big = np.flatnonzero(step > gap_factor * med)
    gaps = tuple((float(t[k]), float(t[k + 1])) for k in big)
    return TorqueInput(t=t, torque=q, linear=interp == "linear", gaps=gaps)
