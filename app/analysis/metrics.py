r"""Ripple metrics of one event: the motor-speed response to a torque reversal.

All metrics are computed on the speed *detrended from the rigid-body trend* and signed
so that the gap-open excursion is positive (``y = direction * (speed - trend)``)::

    y (rpm)          impact peak (gaps close)
      ^                 *                          rise height = y_peak - baseline
      |                / \        .-.              fluctuation = y_peak - y_valley
      |  rise         /   \      /   \   .-.       first overshoot = y_peak - y_final
      |  (gap open)  /     \    /     \_/   \_____ y_final
      | ___________ /       \  /
      |            t_rise    \/ valley (adjacent)
      +-----------|---------|------------------------> t
                  |<------->| rising-edge time (t_rise to t_peak)

The gap-open time itself comes from the free-rotor phase of the raw speed and torque
(:mod:`app.analysis.lash`): the rising edge also holds the shafts unwinding before the gap
opens and is an upper bound of it.

The rigid-body trend is what the speed would do with a stiff, lash-free driveline:
``trend(t) = c0 + c1 (t - t_cross) + g * integral(torque dt)``. With the driveline's
reflected inertia known, ``g = 60 / (2 pi J_eq)`` rpm/(N m s) is fixed and only c0, c1
(road load) are fitted; otherwise g is fitted too. Definitions: docs/metrics.md.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import numpy.typing as npt
from scipy.signal import find_peaks

from app.analysis.lash import NO_GAP, LashParams, free_rotor_interval
from app.analysis.sampling import Spacing, uniform_by_timestamps
from app.analysis.series import FloatArray, noise_rms, parabolic_vertex
from app.errors import InsufficientDataError
from app.serial import Serial
from app.signals import Signal

METRIC_NAMES: tuple[str, ...] = (
    "fluctuation_rpm", "rise_height_rpm", "gap_open_time_s", "rising_edge_time_s", "first_overshoot_rpm",
    "shuffle_freq_hz", "damping_ratio", "settling_time_s",
)
NAN = float("nan")


@dataclass(frozen=True)
class MetricParams:
    peak_lead_s: float = 0.05  # the impact peak may come this long before the torque crossing (timing skew)
    peak_search_s: float = 0.3  # ... and at most this long after it
    baseline_s: float = 0.15  # the rise fit starts this long before the crossing
    min_prominence_rpm: float = 0.5
    settle_fraction: float = 0.05  # settled: within this fraction of the fluctuation ...
    settle_floor_rpm: float = 1.0  # ... or this many rpm (or 3x the noise), whichever is larger
    final_fraction: float = 0.25  # y_final = median over the last quarter of the window
    freq_band_hz: tuple[float, float] = (0.5, 40.0)
    rigid_gain_rpm_per_nms: float | None = None
    # Motor-referred inertia moving with the rotor while the gaps are open (rotor + reducer gears), kg m^2;
    # the gap-open time needs it (the pipeline takes it from the vehicle). None: gap_open_time_s is NaN.
    free_rotor_inertia_kgm2: float | None = None
    lash: LashParams = field(default_factory=LashParams)
    # Resolution the sampling must offer (app.analysis.sampling): coarser sampling nulls the metric with a reason.
    max_gap_period_s: float = 0.012  # gap-open time (20-30 ms phase) needs a mean spacing at most this
    min_samples_per_cycle: float = 6.0  # shuffle frequency and damping need this many samples per period
    fine_samples_per_cycle: float = 10.0  # below this the fluctuation is flagged as approximate (value kept)


@dataclass(frozen=True)
class RippleMetrics(Serial):
    """Metrics of one speed trace around one event (NaN where not determinable)."""

    fluctuation_rpm: float
    rise_height_rpm: float
    gap_open_time_s: float  # free-rotor interval: loss of load to impact (app.analysis.lash)
    rising_edge_time_s: float  # knee of the rise to the impact peak (an upper bound of the gap-open time)
    first_overshoot_rpm: float
    shuffle_freq_hz: float
    damping_ratio: float
    settling_time_s: float  # from the torque zero crossing
    t_gap_open_s: float  # loss of load (free-rotor fit)
    t_gap_close_s: float  # the load comes back (free-rotor fit)
    t_rise_start_s: float  # knee of the rising edge
    t_impact_s: float
    t_valley_s: float
    noise_rpm: float
    sample_period_s: float
    gap_rotor_inertia_kgm2: float  # inertia the speed slope implies while the gap is open
    # metric name -> why the sampling cannot support it; the metric is NaN (null) unless the reason
    # starts with "approximate"
    resolution: dict[str, str] = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in METRIC_NAMES}


def rigid_trend(
    t: FloatArray, speed: FloatArray, torque: Signal, t_ref: float, gain: float | None = None
) -> FloatArray:
    """Least-squares rigid-body trend of ``speed`` (rpm) at times ``t`` (s), shape (n,)."""
    tq = torque.at(t)
    ok = np.isfinite(tq)
    if not ok.any():
        raise InsufficientDataError(f"torque has no samples between {t[0]:.3f} and {t[-1]:.3f} s")
    tq = np.interp(t, t[ok], tq[ok])  # hold the edges where the torque channel starts late / ends early
    integral = np.concatenate(([0.0], np.cumsum(0.5 * (tq[1:] + tq[:-1]) * np.diff(t))))
    x = t - t_ref
    fin = np.isfinite(speed)
    target = speed - (gain * integral if gain is not None else 0.0)
    cols = [np.ones_like(x), x] if gain is not None else [np.ones_like(x), x, integral]
    a = np.column_stack(cols)
    coef, *_ = np.linalg.lstsq(a[fin], target[fin], rcond=None)
    trend = a @ coef
    return trend + (gain * integral if gain is not None else 0.0)


def _adjacent_valley(y: FloatArray, ip: int, peaks: npt.NDArray[np.intp], prom: float) -> int | None:
    """Lowest point between the peak ``ip`` and the next significant peak (None: no real swing)."""
    nxt = peaks[peaks > ip]
    stop = int(nxt[0]) if nxt.size else y.size
    if stop <= ip + 1:
        return None
    iv = ip + 1 + int(np.argmin(y[ip + 1:stop]))
    if iv >= y.size - 1 or y[ip] - y[iv] < prom:
        return None  # still falling at the end of the window, or no real swing
    return iv


def _impact_peak(y: FloatArray, i0: int, i1: int, prom: float) -> tuple[int, int | None] | None:
    """The significant maximum in ``y[i0..i1]`` with the largest swing to its adjacent valley.

    That is the top of the gap-open excursion: a smaller wiggle from the shafts unwinding
    before it has a smaller swing. Returns (peak index, valley index or None).
    """
    peaks, _ = find_peaks(y, prominence=prom)
    inside = peaks[(peaks >= i0) & (peaks <= i1)]
    best: tuple[float, int, int | None] | None = None
    for ip in inside:
        iv = _adjacent_valley(y, int(ip), peaks, prom)
        swing = float(y[ip] - y[iv]) if iv is not None else float(y[ip]) - float(np.min(y[ip:]))
        if best is None or swing > best[0]:
            best = (swing, int(ip), iv)
    if best is not None:
        return best[1], best[2]
    if i1 <= i0:
        return None
    j = i0 + int(np.argmax(y[i0:i1 + 1]))
    rises = y[j] - float(np.min(y[i0:j + 1])) >= prom
    return (j, _adjacent_valley(y, j, peaks, prom)) if i0 < j < y.size - 1 and rises else None


KNEE_ROWS = 256  # grid points of the knee fit evaluated at once: (rows, samples) arrays that stay in cache
KNEE_EDGE = 4  # grid points with this many samples after them or fewer are always evaluated in full
KNEE_TOL = 1e-6  # relative to n var(y): how close to the screened minimum a grid point is evaluated in full
KNEE_DIRECT = 40_000  # grid points x samples up to which every point is evaluated in full without a screen


def _knee_rows(t: FloatArray, y: FloatArray, knots: FloatArray, p: float) -> tuple[FloatArray, FloatArray,
                                                                                 FloatArray]:
    """SSE, slope and mean regressor of ``b + a max(0, t - t0)^p`` at every knot ``t0``: (rows, n) arrays a block of
    rows at a time (each row's sums are the same however the rows are grouped)."""
    n = y.size
    yc = y - y.mean()
    vy = np.var(y)
    sse, a, um = np.empty(knots.size), np.empty(knots.size), np.empty(knots.size)
    for s in range(0, knots.size, KNEE_ROWS):
        d = np.maximum(0.0, t[None, :] - knots[s:s + KNEE_ROWS, None])
        u = d if p == 1.0 else d ** p
        m = u.mean(axis=1)
        cov = (u * yc[None, :]).mean(axis=1)
        var = (u * u).mean(axis=1) - m * m
        with np.errstate(invalid="ignore", divide="ignore"):
            slope = cov / var
            err = n * (vy - cov * cov / var)
        sse[s:s + KNEE_ROWS] = np.where((var > 0) & (slope > 0), err, np.inf)
        a[s:s + KNEE_ROWS], um[s:s + KNEE_ROWS] = slope, m
    return sse, a, um


def _knee_screen(t: FloatArray, y: FloatArray, grid: FloatArray, p: float) -> tuple[FloatArray, npt.NDArray[np.intp]]:
    """The knee fit's SSE at every grid point from running sums (O(grid + n) instead of O(grid n); rounding differs
    from :func:`_knee_rows`), and the number of samples after each grid point.

    Every sum is taken in the distance ``s`` of a sample from the end of the rise, and every regressor
    ``t - t0 = D - s`` with ``D`` the knot's distance from the end: each term is within ``D^4`` of the result,
    whatever the window's length, so the binomial expansions lose no more than a factor 16 to rounding."""
    n = y.size
    sig = t[-1] - t
    d = t[-1] - grid
    yc = y - y.mean()
    first = np.searchsorted(t, grid, side="right")  # the samples after each knot: first..n-1

    def tail(x: FloatArray) -> FloatArray:  # sum of x over the samples after each knot, summed from the end
        return np.concatenate([np.cumsum(x[::-1])[::-1], [0.0]])[first]

    k = (n - first).astype(np.float64)
    s1, s2, b0, b1 = tail(sig), tail(sig ** 2), tail(yc), tail(sig * yc)
    if p == 1.0:
        su, suu, suy = k * d - s1, k * d * d - 2.0 * d * s1 + s2, d * b0 - b1
    else:
        s3, s4, b2 = tail(sig ** 3), tail(sig ** 4), tail(sig * sig * yc)
        su = k * d * d - 2.0 * d * s1 + s2
        suu = k * d ** 4 - 4.0 * d ** 3 * s1 + 6.0 * d * d * s2 - 4.0 * d * s3 + s4
        suy = d * d * b0 - 2.0 * d * b1 + b2
    m, cov = su / n, suy / n
    var = suu / n - m * m
    with np.errstate(invalid="ignore", divide="ignore"):
        sse = n * (np.var(y) - cov * cov / var)
    return np.asarray(np.where((var > 0) & (cov > 0), sse, np.inf), dtype=np.float64), n - first


def _knee_fit(t: FloatArray, y: FloatArray) -> tuple[float, float]:
    """Fit ``b + a max(0, t - t0)^p`` (a > 0, p in {1, 2}) to a rise; return (t0, b).

    ``t0`` runs over a grid of an eighth of the sample spacing. Running sums screen every grid point; the points
    within :data:`KNEE_TOL` of the screened minimum, and those the sums cannot resolve (near the end of the rise),
    are then evaluated in full, so the result is the full evaluation's at every point
    (``tests/analysis/test_metrics.py`` holds the two equal)."""
    step = max(min(float(np.min(np.diff(t))) / 8.0, 1e-3), 1e-5)
    grid = np.arange(t[0], t[-1], step)
    if grid.size == 0:
        return float(t[0]), float(y[0])
    best = (np.inf, float(t[0]), float(y[0]))
    ym = y.mean()
    scale = y.size * float(np.var(y))
    every = np.arange(grid.size)
    for p in (1.0, 2.0):
        rows = every  # a short rise: every point in full costs less than the screen
        if grid.size * y.size > KNEE_DIRECT:
            screened, after = _knee_screen(t, y, grid, p)
            low = float(np.min(screened))
            if low < (1.0 - 1e-3) * scale:  # else nothing fits clearly better than a constant: every point in full
                rows = np.flatnonzero((screened <= low + KNEE_TOL * scale) | (after <= KNEE_EDGE))
        sse, a, um = _knee_rows(t, y, grid[rows], p)
        g = int(np.argmin(sse))
        if sse[g] < best[0]:
            best = (float(sse[g]), float(grid[rows[g]]), float(ym - a[g] * um[g]))
    return best[1], best[2]


def knee_fit_in_full(t: FloatArray, y: FloatArray) -> tuple[float, float]:
    """:func:`_knee_fit` with every grid point evaluated in full, in one (grid, samples) array per power, as the fit
    was first written: the reference the screened fit is held equal to (tests) and timed against (bench/knee.py)."""
    step = max(min(float(np.min(np.diff(t))) / 8.0, 1e-3), 1e-5)
    grid = np.arange(t[0], t[-1], step)
    if grid.size == 0:
        return float(t[0]), float(y[0])
    best = (np.inf, float(t[0]), float(y[0]))
    for p in (1.0, 2.0):
        u = np.maximum(0.0, t[None, :] - grid[:, None]) ** p
        um = u.mean(axis=1)
        cov = (u * (y - y.mean())[None, :]).mean(axis=1)
        var = (u * u).mean(axis=1) - um * um
        with np.errstate(invalid="ignore", divide="ignore"):
            a = cov / var
            sse = np.where((var > 0) & (a > 0), y.size * (np.var(y) - cov * cov / var), np.inf)
        g = int(np.argmin(sse))
        if sse[g] < best[0]:
            best = (float(sse[g]), float(grid[g]), float(y.mean() - a[g] * um[g]))
    return best[1], best[2]


def _alternating_extrema(y: FloatArray, start: int, prom: float) -> list[int]:
    hi, _ = find_peaks(y, prominence=prom)
    lo, _ = find_peaks(-y, prominence=prom)
    marks = sorted([(int(i), 1) for i in hi if i >= start] + [(int(i), -1) for i in lo if i >= start])
    out: list[tuple[int, int]] = []
    for i, s in marks:
        if out and out[-1][1] == s:  # two maxima in a row: keep the more extreme one
            if s * y[i] > s * y[out[-1][0]]:
                out[-1] = (i, s)
            continue
        out.append((i, s))
    return [i for i, _ in out]


def _spectral_peak(y: FloatArray, dt: float, band: tuple[float, float]) -> float:
    if y.size < 8:
        return NAN
    nfft = 1 << int(np.ceil(np.log2(y.size * 16)))
    mag = np.abs(np.fft.rfft(y - y.mean(), nfft))
    f = np.fft.rfftfreq(nfft, dt)
    m = (f >= band[0]) & (f <= band[1])
    if not m.any():
        return NAN
    idx = np.flatnonzero(m)
    k = int(idx[np.argmax(mag[idx])])
    off, _ = parabolic_vertex(mag, k)
    return float(f[k] + off * (f[1] - f[0]))


def ripple_metrics(
    t: FloatArray, speed: FloatArray, torque: Signal, t_cross: float, direction: float,
    params: MetricParams | None = None,
) -> RippleMetrics:
    """Ripple metrics of one speed trace over one event window.

    Parameters
    ----------
    t, speed
        Sample times (s, shape (n,), increasing) and motor speed (rpm) over the event window.
    torque
        Motor torque (N m) covering the window, for the rigid-body trend.
    t_cross
        Torque zero-crossing time (s).
    direction
        +1 for a tip-in, -1 for a tip-out.
    """
    p = params or MetricParams()
    fin = np.isfinite(speed)
    t, speed = t[fin], speed[fin]
    if t.size < 8:
        raise InsufficientDataError(f"{t.size} speed samples in the event window; need at least 8")
    t_raw, speed_raw = t, speed
    t, speed, sp = uniform_by_timestamps(t, speed)  # bursty stream: uniform at its mean spacing
    if t.size < 8:
        raise InsufficientDataError(f"{t.size} samples at the mean spacing {sp.mean_s * 1e3:.1f} ms; need at least 8")
    dt = sp.mean_s
    y = direction * (speed - rigid_trend(t, speed, torque, t_cross, p.rigid_gain_rpm_per_nms))
    # the noise floor from the samples as logged: interpolation onto the grid would average the noise down
    y_raw = y if t is t_raw else direction * (speed_raw - rigid_trend(t_raw, speed_raw, torque, t_cross,
                                                                        p.rigid_gain_rpm_per_nms))
    pre = t_raw < t_cross - p.peak_lead_s
    noise = noise_rms(y_raw[pre]) if np.sum(pre) > 8 else noise_rms(y_raw)
    final = float(np.median(y[int(y.size * (1.0 - p.final_fraction)):]))
    i0 = int(np.searchsorted(t, t_cross - p.peak_lead_s))
    i1 = int(np.searchsorted(t, t_cross + p.peak_search_s, side="right")) - 1
    span = float(np.ptp(y[i0:])) if i0 < y.size else 0.0
    prom = max(p.min_prominence_rpm, 4.0 * noise, 0.1 * span)
    found = _impact_peak(y, i0, min(i1, y.size - 1), prom)
    lash = NO_GAP
    if p.free_rotor_inertia_kgm2 is not None:
        lash = free_rotor_interval(t, speed, torque, t_cross, direction, p.free_rotor_inertia_kgm2, noise, p.lash)
    if found is None:
        return _resolution_checked(RippleMetrics(
            NAN, NAN, lash.duration_s, NAN, NAN, NAN, NAN, NAN, lash.t_open_s, lash.t_close_s,
            NAN, NAN, NAN, noise, dt, lash.rotor_inertia_kgm2), sp, p)
    ip, iv = found
    off_p, y_peak = parabolic_vertex(y, ip)
    t_peak = float(t[ip] + off_p * dt)

    y_valley, t_valley = NAN, NAN
    if iv is not None:
        off_v, y_valley = parabolic_vertex(y, iv)
        t_valley = float(t[iv] + off_v * dt)

    ib = int(np.searchsorted(t, t_cross - p.baseline_s))
    t_open, base = _knee_fit(t[ib:ip + 1], y[ib:ip + 1]) if ip - ib >= 3 else (NAN, NAN)

    ext = _alternating_extrema(y, ip, max(p.min_prominence_rpm, 4.0 * noise, 0.02 * (y_peak - final)))
    if ext and ext[0] != ip:
        ext = [ip, *[i for i in ext if i > ip]]
    use = ext[1:] if len(ext) >= 4 else ext  # the impact peak is not part of the free oscillation
    vals, times = [], []
    for i in use:
        off, v = parabolic_vertex(y, i)
        vals.append(v)
        times.append(float(t[i] + off * dt))
    # Half-cycle peak-to-peak swings cancel a constant detrending offset; stop once they sink into the noise.
    swings = np.abs(np.diff(np.asarray(vals)))
    small = np.flatnonzero(swings < max(6.0 * noise, 0.05 * swings[0])) if swings.size else np.zeros(1, int)
    keep = int(small[0]) if small.size else swings.size  # usable swings, each spanning half a period
    zeta = NAN
    if keep >= 2:
        delta = 2.0 * float(np.mean(np.log(swings[:keep - 1] / swings[1:keep])))  # swings are half a period apart
        # growing swings (delta <= 0) mean a second excitation, not a free decay: no damping ratio
        zeta = delta / float(np.sqrt(4.0 * np.pi**2 + delta**2)) if delta > 0 else NAN
    if keep >= 2:
        freq = keep / (2.0 * (times[keep] - times[0]))
    else:
        freq = _spectral_peak(y[ip:] - final, dt, p.freq_band_hz)

    band = max(p.settle_fraction * (y_peak - y_valley if np.isfinite(y_valley) else y_peak - final),
               p.settle_floor_rpm, 3.0 * noise)
    outside = np.flatnonzero(np.abs(y[ip:] - final) > band)
    settle = NAN
    if outside.size and ip + int(outside[-1]) < y.size - 1:
        settle = float(t[ip + int(outside[-1]) + 1] - t_cross)
    elif not outside.size:
        settle = t_peak - t_cross

    return _resolution_checked(RippleMetrics(
        fluctuation_rpm=y_peak - y_valley if np.isfinite(y_valley) else NAN,
        rise_height_rpm=y_peak - base if np.isfinite(base) else NAN,
        gap_open_time_s=lash.duration_s,
        rising_edge_time_s=t_peak - t_open if np.isfinite(t_open) else NAN,
        first_overshoot_rpm=y_peak - final,
        shuffle_freq_hz=freq,
        damping_ratio=zeta,
        settling_time_s=settle,
        t_gap_open_s=lash.t_open_s,
        t_gap_close_s=lash.t_close_s,
        t_rise_start_s=t_open,
        t_impact_s=t_peak,
        t_valley_s=t_valley,
        noise_rpm=noise,
        sample_period_s=dt,
        gap_rotor_inertia_kgm2=lash.rotor_inertia_kgm2,
    ), sp, p)


def _resolution_checked(m: RippleMetrics, sp: Spacing, p: MetricParams) -> RippleMetrics:
    """``m`` with the metrics its sampling cannot resolve set to NaN, each with the reason.

    The sampling period is the mean spacing of the actual time stamps (``sp``), not the median
    of a bursty stream. Gap-open time needs ``max_gap_period_s``; shuffle frequency and damping
    ratio need ``min_samples_per_cycle`` samples per shuffle period at the mean spacing and half
    as many at the longest gap (a burst stream's gaps alias a fast shuffle to a slower one,
    so the frequency found is not trusted either); the fluctuation is kept
    but flagged below ``fine_samples_per_cycle`` (the peak and valley fall between samples).
    """
    why: dict[str, str] = {}
    dt = sp.mean_s
    where = f"mean spacing {dt * 1e3:.1f} ms, max {sp.max_s * 1e3:.1f} ms"
    changes: dict[str, float] = {}
    if dt > p.max_gap_period_s:
        why["gap_open_time_s"] = (f"sampling too coarse for the gap-open time: {where}; needs a mean spacing "
                                  f"<= {p.max_gap_period_s * 1e3:.0f} ms")
        changes.update(gap_open_time_s=NAN, t_gap_open_s=NAN, t_gap_close_s=NAN)
    f = m.shuffle_freq_hz
    if np.isfinite(f) and f > 0:
        per_cycle, at_max = 1.0 / (f * dt), 1.0 / (f * sp.max_s)
        if per_cycle < p.min_samples_per_cycle or at_max < p.min_samples_per_cycle / 2:
            text = (f"sampling too coarse for the shuffle: {per_cycle:.1f} samples per period at {f:.1f} Hz "
                    f"({at_max:.1f} at the longest gap; {where}); needs {p.min_samples_per_cycle:g} "
                    f"({p.min_samples_per_cycle / 2:g} at the longest gap)")
            why["shuffle_freq_hz"] = why["damping_ratio"] = text
            changes.update(shuffle_freq_hz=NAN, damping_ratio=NAN)
        if per_cycle < p.fine_samples_per_cycle and np.isfinite(m.fluctuation_rpm):
            why["fluctuation_rpm"] = (f"approximate: {per_cycle:.1f} samples per shuffle period ({where}); "
                                      "peak and valley may fall between samples")
    if not why:
        return m
    return replace(m, resolution=why, **changes)
