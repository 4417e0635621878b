r"""ISO 2631-1 frequency weighting W_d and the vibration dose value (whole-body vibration, seated, x-axis).

ISO 2631-1:1997 (Annex A) builds every weighting from three analogue stages; for W_d (horizontal,
seated occupant, x and y axes)::

    band limit, high pass   H_h(s) = s^2 / (s^2 + w1 s / Q1 + w1^2)             f1 = 0.4 Hz, Q1 = 1/sqrt 2
    band limit, low pass    H_l(s) = w2^2 / (s^2 + w2 s / Q1 + w2^2)            f2 = 100 Hz
    a-v transition          H_t(s) = (1 + s / w3) / (1 + s / (Q4 w4) + s^2 / w4^2)   f3 = f4 = 2 Hz, Q4 = 0.63

(W_d has no upward step). ``|W_d|`` is about 1.01 at 1 Hz, 0.89 at 2 Hz, 0.51 at 4 Hz, 0.253 at 8 Hz
and 0.125 at 16 Hz: the body feels the low-frequency shuffle (2-10 Hz) much more than a clunk.

The digital filter is the bilinear transform of the analogue one at the signal's sampling rate,
applied causally as the standard and ISO 8041 instruments do (a weighting is a phase response as
well as a gain, and the dose value depends on it). The low-pass band limit is left out when
``f2`` is above 0.45 of the sampling rate (a 100 Hz accelerometer cannot carry it; its effect
below 40 Hz is under 1 %). The filter starts in the steady state of the first sample, so a
constant acceleration (grade, an offset) gives no start-up transient.

The vibration dose value over a record of duration T::

    VDV = ( integral_0^T a_w(t)^4 dt )^(1/4)          m/s^1.75

the fourth power weights the peaks (a shuffle burst or a clunk) more than the RMS does.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from scipy import signal as sps

from app.analysis.feel_kernels import fourth_power_dose
from app.analysis.series import FloatArray
from app.analysis.zerophase import sections

F1_HZ, F2_HZ, Q1 = 0.4, 100.0, 1.0 / math.sqrt(2.0)
F3_HZ, F4_HZ, Q4 = 2.0, 2.0, 0.63
LOWPASS_MAX_FRACTION = 0.45  # the band-limit low pass is used only below this fraction of fs


def wd_gain(f_hz: FloatArray | float) -> FloatArray:
    """``|W_d(j 2 pi f)|`` of the analogue weighting (all three stages), shape of ``f_hz``."""
    s = 2j * np.pi * np.asarray(f_hz, dtype=np.float64)
    w1, w2, w3, w4 = (2 * np.pi * f for f in (F1_HZ, F2_HZ, F3_HZ, F4_HZ))
    hh = s**2 / (s**2 + w1 * s / Q1 + w1**2)
    hl = w2**2 / (s**2 + w2 * s / Q1 + w2**2)
    ht = (1 + s / w3) / (1 + s / (Q4 * w4) + s**2 / w4**2)
    return np.asarray(np.abs(hh * hl * ht), dtype=np.float64)


@functools.lru_cache(maxsize=16)
def wd_sos(fs_hz: float) -> FloatArray:
    """Second-order sections of the digital W_d at sampling rate ``fs_hz`` (bilinear transform)."""
    w1, w2, w3, w4 = (2 * np.pi * f for f in (F1_HZ, F2_HZ, F3_HZ, F4_HZ))
    num = np.polymul([1.0, 0.0, 0.0], [1.0 / w3, 1.0])
    den = np.polymul([1.0, w1 / Q1, w1**2], [1.0 / w4**2, 1.0 / (Q4 * w4), 1.0])
    if LOWPASS_MAX_FRACTION * fs_hz > F2_HZ:
        num = np.polymul(num, [w2**2])
        den = np.polymul(den, [1.0, w2 / Q1, w2**2])
    z, p, k = sps.tf2zpk(num, den)
    zd, pd, kd = sps.bilinear_zpk(z, p, k, fs_hz)
    return np.asarray(sps.zpk2sos(zd, pd, kd), dtype=np.float64)


@functools.lru_cache(maxsize=16)
def _zi(fs_hz: float) -> FloatArray:
    return np.asarray(sps.sosfilt_zi(wd_sos(fs_hz)), dtype=np.float64)


def weighted(a: FloatArray, fs_hz: float) -> FloatArray:
    """``a`` (m/s^2, uniform at ``fs_hz``) through W_d, starting in the steady state of ``a[0]``."""
    rate = float(f"{fs_hz:.6g}")
    return sections(wd_sos(rate), _zi(rate), np.asarray(a, dtype=np.float64))


def vdv(a: FloatArray, fs_hz: float) -> float:
    """Vibration dose value (m/s^1.75) of uniform samples ``a`` (m/s^2) at ``fs_hz``, W_d weighted."""
    a = np.asarray(a, dtype=np.float64)
    if a.size < 2 or not np.isfinite(a).all():
        return float("nan")
    rate = float(f"{fs_hz:.6g}")
    return float(fourth_power_dose(wd_sos(rate), _zi(rate), np.ascontiguousarray(a), fs_hz))
