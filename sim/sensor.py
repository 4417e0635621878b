"""Inverter speed signal: what the reported motor speed looks like after the inverter.

The first-order filter (``effects.speed_sensor.tau_s``) runs inside the compiled integrator at
the full step; transport delay, sample-and-hold and quantisation are applied here on the
output grid.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]


def delay_sample_quantize(t: F64, y: F64, delay_s: float, sample_s: float, resolution: float) -> F64:
    """Apply delay, zero-order-hold sampling and rounding to a signal on grid ``t``.

    Parameters
    ----------
    t : (n,) s, increasing
    y : (n,) signal, e.g. rpm
    delay_s : transport delay (s); before ``t[0] + delay_s`` the first value is held
    sample_s : sensor sample period (s); 0 = continuous
    resolution : quantisation step in the units of ``y``; 0 = none

    Returns
    -------
    (n,) the processed signal on the same grid.
    """
    out = np.asarray(y, dtype=np.float64)
    if delay_s > 0:
        out = np.interp(t - delay_s, t, out)
    if sample_s > 0:
        k = np.floor((t - t[0]) / sample_s + 1e-9)
        out = np.interp(t[0] + k * sample_s, t, out)
    if resolution > 0:
        out = np.round(out / resolution) * resolution
    return out
