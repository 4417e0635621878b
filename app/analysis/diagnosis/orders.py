"""Motor-order tones in the speed channel: structure that the noise floor would take for noise.

A motor's torque ripple (cogging, current-sensor offsets, slot harmonics) and a resolver's angle
error both put a tone on the measured speed that is locked to the rotor angle: at mechanical order
``k`` its frequency is ``k * rpm / 60`` Hz. At 2 500 rpm the first order is 42 Hz; in a 100 Hz CAN
speed channel it is sampled close to Nyquist and looks like white noise to the second-difference
estimator of :mod:`.noise` -- which then inflates the floor (a tone near Nyquist adds about twice its
variance to the second differences) and hides both the tone and any faint effect under it.

Order tracking finds it without a model: the rotor angle is the integral of the measured speed, so
within a short block the speed is regressed on ``cos(k theta)`` and ``sin(k theta)`` (beside a local
quadratic trend), whatever the aliasing. Under white noise the energy the two tone columns take is
``sigma^2 chi^2(2)`` per block; pooled over blocks it is an F test against the blocks' own residual
(so an inflated floor cannot hide it). Orders are tested one at a time and the most significant is
removed before the next is tested (up to :data:`MAX_TONES`).

Blocks where an order aliases below :data:`MIN_ALIAS_HZ` (where the shuffle and its decaying tails
would take the tone columns for a tone) or within :data:`NYQUIST_MARGIN_HZ` of Nyquist (the sine
column vanishes) are skipped for that order. A tone found here is reported
beside the decision as structured remainder that no candidate in the library models.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy import stats

from app.serial import Serial

FloatArray = npt.NDArray[np.float64]

ORDERS = tuple(range(1, 25))  # mechanical orders tested: 1..24 covers pole-pair multiples of common PMSMs
BLOCK_S = 0.3  # block length: the speed changes little, and the phase error of the integrated speed is tiny
MIN_BLOCKS = 3  # quiet time is scarce on a drive with close reversals; a tone worth a flag shows in a few blocks
MIN_ALIAS_HZ = 12.0  # below this the driveline's own shuffle (2-10 Hz) and its decaying tails live
NYQUIST_MARGIN_HZ = 1.5
ALPHA = 1e-6  # per order (a false tone on a clean log costs a wrong "structured" flag)
MAX_TONES = 3
# a tone is flagged when its power (a^2 / 2) is at least half the white noise's (a >= sigma): the same excess over
# noise that makes a residual a gap (DecisionRules.min_gap_ratio 1.5); smaller ones were found on clean drives at
# high orders (0.16-0.3 rpm, p ~ 1e-8), where the quantised, jittered channel is not quite white
MIN_AMPLITUDE_SIGMAS = 1.0
OUTLIER_RSS = 5.0  # a block whose trend residual exceeds this many times the median holds a transient: left out


@dataclass(frozen=True)
class OrderTone(Serial):
    """A tone locked to the rotor angle.

    Attributes
    ----------
    order : mechanical order (tones per rotor revolution).
    amplitude_rpm : median amplitude over the blocks (rpm, zero to peak).
    f_stat : pooled F statistic (tone energy per degree of freedom over residual energy per one).
    p_value : its p-value under white noise.
    blocks : blocks that tested it.
    """

    order: int
    amplitude_rpm: float
    f_stat: float
    p_value: float
    blocks: int

    def describe(self) -> str:
        return f"motor order {self.order} ({self.amplitude_rpm:.2f} rpm)"


def _blocks(t: FloatArray, quiet: npt.NDArray[np.bool_], period: float) -> npt.NDArray[np.int64]:
    """(B, m) sample indices of blocks of ``m`` consecutive quiet samples one period apart."""
    m = max(round(BLOCK_S / period), 12)  # at least 12 samples for 5 columns
    d = np.diff(t)
    link = (d > 0.5 * period) & (d < 1.5 * period) & quiet[:-1] & quiet[1:]  # sample i -> i + 1 usable
    edges = np.flatnonzero(np.diff(np.concatenate([[0], link.astype(np.int8), [0]])))
    out: list[npt.NDArray[np.int64]] = []
    for a, b in zip(edges[::2], edges[1::2], strict=True):  # links a..b-1 join samples a..b
        for s in range(a, b + 2 - m, m):
            out.append(np.arange(s, s + m))
    return np.array(out, dtype=np.int64).reshape(-1, m)


def _lsq(a: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per-block least squares of ``y`` (B, m) on columns ``a`` (B, m, c): (coefficients, residual)."""
    ata = np.einsum("bmi,bmj->bij", a, a) + 1e-12 * np.eye(a.shape[2])
    c = np.linalg.solve(ata, np.einsum("bmi,bm->bi", a, y)[..., None])[..., 0]
    return c, y - np.einsum("bmi,bi->bm", a, c)


def _trend(x: FloatArray) -> FloatArray:
    """(B, m, 3) columns of a local quadratic."""
    return np.stack([np.ones_like(x), x, x * x], axis=2)


def _tone_fit(y: FloatArray, x: FloatArray, phase: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per block: (energy the tone columns take, residual energy with them, fitted tone (B, m))."""
    trend = _trend(x)
    full = np.concatenate([trend, np.cos(phase)[..., None], np.sin(phase)[..., None]], axis=2)
    _, r0 = _lsq(trend, y)
    c, r1 = _lsq(full, y)
    tone = np.einsum("bmi,bi->bm", full[..., 3:], c[:, 3:])
    return (r0 * r0).sum(axis=1) - (r1 * r1).sum(axis=1), (r1 * r1).sum(axis=1), tone


def find_order_tones(t: FloatArray, rpm: FloatArray, quiet: npt.NDArray[np.bool_], period: float
                     ) -> tuple[list[OrderTone], FloatArray, npt.NDArray[np.bool_]]:
    """Significant motor-order tones, the speed with them removed, and the samples where every one was removed
    (blocks where an order aliased out of the tested band keep it).

    Parameters
    ----------
    t : (n,) sample times (s), increasing.
    rpm : (n,) measured motor speed (rpm), finite.
    quiet : (n,) samples away from transients.
    period : nominal sample period (s).
    """
    t = np.asarray(t, dtype=np.float64)
    v = np.asarray(rpm, dtype=np.float64).copy()
    blocks = _blocks(t, np.asarray(quiet, dtype=bool), period)
    if blocks.shape[0] < MIN_BLOCKS:
        return [], v, np.zeros(t.size, dtype=bool)
    # rotor angle (rad) from the measured speed; each block's own constant phase is absorbed by the fit
    theta = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))]) * (2.0 * np.pi / 60.0)
    # blocks holding a transient (a quadratic leaves far more than the others) would swamp the pooled residual
    _, r = _lsq(_trend((t[blocks] - t[blocks].mean(axis=1, keepdims=True)) / BLOCK_S), v[blocks])
    r_trend = (r * r).sum(axis=1)
    blocks = blocks[r_trend <= OUTLIER_RSS * float(np.median(r_trend))]
    if blocks.shape[0] < MIN_BLOCKS:
        return [], v, np.zeros(t.size, dtype=bool)
    clean = np.ones(blocks.shape[0], dtype=bool)  # blocks where every tone found so far was removed
    tb = t[blocks]
    x = (tb - tb.mean(axis=1, keepdims=True)) / BLOCK_S
    f_rev = np.abs(v[blocks].mean(axis=1)) / 60.0
    fs = 1.0 / period
    found: list[OrderTone] = []
    for _ in range(MAX_TONES):
        y = v[blocks]
        best: tuple[float, npt.NDArray[np.bool_], FloatArray, OrderTone] | None = None
        for k in ORDERS:
            fa = np.abs((k * f_rev + fs / 2) % fs - fs / 2)
            use = (fa >= MIN_ALIAS_HZ) & (fa <= fs / 2 - NYQUIST_MARGIN_HZ)
            if int(use.sum()) < MIN_BLOCKS or any(tone.order == k for tone in found):
                continue
            ess, rss, tone = _tone_fit(y[use], x[use], k * theta[blocks[use]])
            dfn, dfd = 2 * int(use.sum()), int(use.sum()) * (blocks.shape[1] - 5)
            f_stat = float((ess.sum() / dfn) / max(rss.sum() / dfd, 1e-300))
            p = float(stats.f.sf(f_stat, dfn, dfd))
            amp = float(np.median(np.sqrt(2.0 * np.mean(tone * tone, axis=1))))
            sigma = float(np.sqrt(rss.sum() / dfd))  # the blocks' own noise with the tone removed
            if p < ALPHA and amp >= MIN_AMPLITUDE_SIGMAS * sigma and (best is None or f_stat > best[0]):
                sel = np.flatnonzero(use)
                full_tone = np.zeros_like(y)
                full_tone[sel] = tone
                best = (f_stat, use, full_tone, OrderTone(k, amp, f_stat, p, int(use.sum())))
        if best is None:
            break
        found.append(best[3])
        v[blocks] = v[blocks] - best[2]
        clean &= best[1]
    tested = np.zeros(t.size, dtype=bool)
    tested[blocks[clean].ravel()] = True
    return found, v, tested
