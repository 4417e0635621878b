"""Model-free noise floor of a measured speed channel.

The diagnosis must know how much of the residual *no* model could ever explain: sensor noise,
DBC quantisation and timestamp jitter. All three are estimated from the measured data alone,
without any simulation, so the floor cannot be bent by a fit:

- **sample period and jitter** from the timestamp differences (the period by
  :func:`app.analysis.sampling.sample_period`, the rule the analysis uses as well): with ``t_k = kT + j_k`` the
  differences are ``T + j_{k+1} - j_k``, so their robust spread is ``sqrt(2)`` times the jitter;
  dropped frames (differences near ``2T``, ``3T``...) are folded back onto ``T`` first;
- **white noise** from second differences on quiet samples (away from events):
  ``var(x[i+1] - 2x[i] + x[i-1]) = 6 sigma^2`` for white noise, while a slowly varying signal
  contributes almost nothing;
- **quantisation** as the smallest step between distinct values, ``q^2 / 12``, as a lower bound
  when the noise is too small to dither the quantiser.

A timestamp error ``e`` on a sample of a signal changing at ``v'`` rpm/s looks like a speed error
``v' e``; :meth:`NoiseFloor.variance` turns the jitter into a per-sample variance from the measured
slope (again model-free).

The *torque* channel's quantisation step and white noise are estimated the same way
(``torque_step_nm``, ``torque_sigma_nm``): while the torque is held, its CAN value is off by one
fixed amount up to half a step, which the vehicle inertia integrates into a speed drift; and noise
on the samples makes the simulated driveline ring where the real one does not (see
:mod:`.uncertainty`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.analysis.diagnosis.orders import OrderTone, find_order_tones
from app.analysis.sampling import sample_period
from app.analysis.series import quantisation_step
from app.errors import InsufficientDataError
from app.serial import Serial

FloatArray = npt.NDArray[np.float64]

_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class NoiseFloor(Serial):
    """Noise of a measured speed channel, estimated without a model.

    Attributes
    ----------
    sigma_rpm : white noise standard deviation (rpm), at least ``quant_step_rpm / sqrt(12)``.
    quant_step_rpm : smallest step between distinct values (rpm); 0 when not quantised.
    jitter_s : standard deviation of timestamp jitter (s).
    period_s : nominal sample period (s).
    n_samples : number of second differences the white-noise estimate used.
    torque_step_nm : quantisation step of the torque channel (N m); 0 when not quantised or unknown.
    torque_sigma_nm : white noise standard deviation of the torque channel (N m), from its second
        differences like the speed's (without the quantisation floor: held values are
        ``torque_step_nm``'s part); 0 when the torque is clean or unknown.
    tones : motor-order tones found in the speed (:mod:`.orders`); ``sigma_rpm`` is then estimated
        with them removed, since a tone is structure, not noise.
    retimed_bursts, retimed_frames, unresolved_bursts : runs of frames a buffering logger wrote
        back-to-back, re-timed before anything else (:mod:`.retime`; torque and speed together), the
        frames moved, and runs left as logged because frames were lost in them too.
    """

    sigma_rpm: float
    quant_step_rpm: float
    jitter_s: float
    period_s: float
    n_samples: int
    torque_step_nm: float = 0.0
    torque_sigma_nm: float = 0.0
    tones: tuple[OrderTone, ...] = ()
    retimed_bursts: int = 0
    retimed_frames: int = 0
    unresolved_bursts: int = 0

    def variance(self, slope_rpm_s: npt.ArrayLike) -> FloatArray:
        """Per-sample residual variance (rpm^2) no model can remove, for samples with slope ``slope_rpm_s``."""
        s = np.asarray(slope_rpm_s, dtype=np.float64)
        return self.sigma_rpm**2 + (self.jitter_s * s) ** 2


def timestamp_jitter(t: FloatArray, period_s: float) -> float:
    """Jitter standard deviation (s) from timestamp differences folded onto the nominal period."""
    d = np.diff(np.asarray(t, dtype=np.float64))
    k = np.maximum(np.round(d / period_s), 1.0)
    dev = d - k * period_s
    if dev.size < 3:
        return 0.0
    # a slow clock-rate mismatch shifts every difference equally; the median removes it
    dev = dev - np.median(dev)
    return float(_MAD_TO_SIGMA * np.median(np.abs(dev)) / np.sqrt(2.0))


def estimate_noise_floor(t: FloatArray, values: FloatArray, quiet: npt.NDArray[np.bool_] | None = None) -> NoiseFloor:
    """Estimate the noise floor of a measured channel.

    Parameters
    ----------
    t : (n,) sample times (s), increasing.
    values : (n,) samples (rpm).
    quiet : (n,) optional mask of samples away from transients (e.g. outside event windows);
        second differences are taken where three consecutive quiet samples are one period apart.
        When fewer than 20 such triples exist, all samples are used.

    Returns
    -------
    NoiseFloor
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    t, v = t[ok], v[ok]
    if t.size < 5:
        raise InsufficientDataError(f"speed channel has {t.size} valid samples; a noise floor needs at least 5")
    period = sample_period(t)
    jitter = timestamp_jitter(t, period)
    q = quantisation_step(v)
    mask = None if quiet is None else np.asarray(quiet, bool)[ok]
    tones, clean, tested = find_order_tones(t, v, np.ones(t.size, bool) if mask is None else mask, period)
    if tones:  # the floor of what no model explains is measured where the tones were removed
        v, mask = clean, tested
    d2 = _second_differences(t, v, mask, period)
    sigma, held = _mad_sigma(d2)
    n_used = int(d2.size)
    if held:
        # the quantiser was not dithered: the MAD is zero, fall back to the RMS, which sees the rare steps
        sigma = held
    sigma = max(sigma, q / np.sqrt(12.0), 1e-6)
    return NoiseFloor(float(sigma), q, jitter, period, n_used, tones=tuple(tones))


def _second_differences(t: FloatArray, v: FloatArray, quiet: npt.NDArray[np.bool_] | None,
                        period: float) -> FloatArray:
    """Second differences of three consecutive samples one period apart (all quiet, when at least 20 are)."""
    d = np.diff(t)
    regular = (d > 0.5 * period) & (d < 1.5 * period)
    triple = regular[:-1] & regular[1:]
    if quiet is not None:
        triple_q = triple & quiet[:-2] & quiet[1:-1] & quiet[2:]
        if int(triple_q.sum()) >= 20:
            triple = triple_q
    return np.asarray((v[2:] - 2.0 * v[1:-1] + v[:-2])[triple], dtype=np.float64)


def _mad_sigma(d2: FloatArray) -> tuple[float, float]:
    """White-noise sigma from second differences ``d2``: ``(sigma from the MAD, sigma from the RMS when the
    MAD is zero else 0)``; ``(0, 0)`` for fewer than three."""
    if d2.size < 3:
        return 0.0, 0.0
    mad = float(np.median(np.abs(d2 - np.median(d2))))
    if mad == 0.0:
        return 0.0, float(np.sqrt(np.mean(d2**2) / 6.0))
    return _MAD_TO_SIGMA * mad / np.sqrt(6.0), 0.0


TRIM_SIGMAS = 5.0  # second differences further than this many MAD-sigmas from their median are transients


def white_noise_sigma(t: FloatArray, values: FloatArray, quiet: npt.NDArray[np.bool_] | None = None) -> float:
    """White-noise sigma of a channel (its unit) from second differences on quiet samples, without a
    quantisation floor; 0 when the samples are held or too few (used for the torque channel).

    The MAD only finds the transients (ramp corners): the sigma is the RMS of the second differences
    within ``TRIM_SIGMAS`` MAD-sigmas of their median. On a channel whose noise is a few quantisation
    steps (0.3 N m on a 0.1 N m DBC step) the MAD of the integer-step differences moves in whole steps,
    and the MAD-sigma came out 0.24 or 0.30 N m on two drives with the same 0.3 N m noise; the trimmed
    RMS has no such steps.
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    ok = np.isfinite(v)
    if int(ok.sum()) < 5:
        return 0.0
    t, v = t[ok], v[ok]
    period = sample_period(t)
    q = None if quiet is None else np.asarray(quiet, bool)[ok]
    d2 = _second_differences(t, v, q, period)
    sigma, _ = _mad_sigma(d2)
    if sigma <= 0.0:
        return 0.0
    dev = d2 - np.median(d2)
    kept = dev[np.abs(dev) <= TRIM_SIGMAS * np.sqrt(6.0) * sigma]
    return float(np.sqrt(np.mean(kept * kept) / 6.0)) if kept.size >= 3 else float(sigma)


def measured_slope(t: FloatArray, values: FloatArray) -> FloatArray:
    """Slope (rpm/s) of a measured series by central differences over one sample each side."""
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if t.size < 3:
        return np.zeros_like(v)
    return np.asarray(np.gradient(v, t), dtype=np.float64)
