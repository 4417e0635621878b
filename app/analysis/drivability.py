r"""Drivability criteria of one event: what the occupants feel, from the longitudinal acceleration.

Input: the vehicle's longitudinal acceleration ``a(t)`` (m/s^2, positive forward) on a uniform
grid around one tip-in or tip-out, the event's torque zero crossing ``t_cross``, its direction
``d`` (+1 tip-in, -1 tip-out), optionally the pedal and the time the lash closed. Two zero-phase
filters (4th-order Butterworth run forwards and backwards, so no filter delay moves a peak):

* the **drivability band**: low pass at ``lowpass_hz`` (20 Hz; at most 0.4 fs) -> ``a_lp``;
* the **clunk band**: band pass ``clunk_band_hz`` (20-200 Hz; the upper edge at most 0.45 fs) -> ``a_hf``.

With ``y = d * a_lp`` (the response in the direction of the torque change)::

    y  (m/s^2)        kick peak
     ^                 *        p-p (first swing)
     |                / \   .-.  <- extrema t_k, y_k
     |               /   \_/   \__.-.___________ settled level a_set
     |  a_pre ______/    valley
     +--------|----|--------------------------------> t
           pedal  first rise (10 % of the kick peak above a_pre)

``a_pre``        median of ``a_lp`` over ``[t_start, t_cross - pre_gap_s]``
``fit``          ``c + A exp(-sigma tau) cos(omega tau + phi)``, ``tau = t - t_kick``, fitted by least squares
                 (Levenberg-Marquardt) to ``y`` over up to ``FIT_PERIODS`` periods from the kick peak,
                 started at the motor speed's shuffle frequency when known, else at the extrema's
``settled``      ``a_set = d c`` (the oscillation's centre, exact while it has not died out by the window's
                 end); without a fit the median of ``a_lp`` over the last ``final_fraction`` of the window
``kick``         ``d (a_peak - a_set)``: the first prominent peak of ``y`` after ``t_cross - peak_lead_s``
                 (vertex on a windowed-sinc interpolation below 500 Hz), over the settled level
``shuffle p-p``  the largest swing ``|y_k - y_{k+1}|`` between successive prominent extrema from the kick
                 peak on (normally the first: kick peak to the following valley)
``frequency``    ``omega / 2 pi`` of the fit; without one ``1 / (2 mean(t_{k+1} - t_k))`` over the extrema
``decay``        damping ratio ``sigma / sqrt(sigma^2 + omega^2)`` of the fit; without one from the logarithmic
                 decrement of successive swings, ``zeta = delta / sqrt(4 pi^2 + delta^2)``
``max jerk``     ``max |d a_lp / dt|`` (m/s^3) from ``t_cross - peak_lead_s`` to the end of the window
``clunk``        ``max |a_hf|`` (m/s^2) within ``[t_close - clunk_before_s, t_close + clunk_after_s]``,
                 ``t_close`` the lash closure (from the speed metrics; else the kick's first rise)
``VDV``          vibration dose value of the whole window, ISO 2631-1 W_d (:mod:`app.analysis.iso2631`)
``response delay`` first rise time minus the pedal's first move (``|pedal - pedal_pre|`` beyond
                 ``max(pedal_min_pct, pedal_fraction x step)``), both linearly interpolated

For an acceleration derived from speed (``noise_ms2`` given) kick and peak-to-peak are read off the fit
(its first peak and the valley after it), which averages the differentiator's noise out.

A criterion the data cannot support is NaN (JSON null) with a reason in ``resolution``: too few
extrema for a frequency, a clunk band above what the sampling carries, no pedal channel, a
saturated sensor in the window, or an acceleration derived from speed whose bandwidth is below
``bandwidth_factor`` x the shuffle frequency or whose fitted amplitude is uncertain by more than
``max_fit_error`` (marked ``unresolved``). Definitions in docs/drivability.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import optimize

from app.analysis.feel_kernels import (
    FIT_OK,
    damped_sine_fit,
    max_abs_slope,
    median,
    residual_rms,
    sinc_refine,
    zigzag,
)
from app.analysis.iso2631 import vdv
from app.analysis.series import FloatArray, parabolic_vertex
from app.analysis.zerophase import butter_sos, zero_phase
from app.serial import Serial
from app.signals import Signal

#: criterion -> unit (the order of every table, CSV and store column)
CRITERIA: dict[str, str] = {
    "response_delay_s": "s",
    "kick_ms2": "m/s^2",
    "shuffle_pp_ms2": "m/s^2",
    "shuffle_freq_hz": "Hz",
    "shuffle_damping_ratio": "-",
    "max_jerk_ms3": "m/s^3",
    "clunk_ms2": "m/s^2",
    "vdv_ms175": "m/s^1.75",
    "settled_accel_ms2": "m/s^2",
}
CRITERIA_NAMES: tuple[str, ...] = tuple(CRITERIA)
NAN = float("nan")
REFINE_BELOW_HZ = 500.0
FIT_PERIODS = 4.0  # the damped-sine fit spans this many shuffle periods from the kick peak (or the window)
CLUNK_PAD_S = 0.15  # the clunk band is filtered over its search interval and this much on either side
_TAPS = np.arange(-8, 9)
_OFFSETS = np.linspace(-1.0, 1.0, 81)
# windowed-sinc interpolation weights, (offsets, taps): value at i + offset = sum_k y[i + k] w[offset, k]
_SINC = np.sinc(_OFFSETS[:, None] - _TAPS[None, :]) * np.kaiser(_TAPS.size + 2, 6.0)[1:-1][None, :]
_SINC /= _SINC.sum(axis=1)[:, None]  # unit gain at every offset


@dataclass(frozen=True)
class DrivabilityParams:
    enabled: bool = True  # compute the criteria in an analysis
    lowpass_hz: float = 20.0  # drivability band (kick, shuffle, jerk, settled)
    clunk_band_hz: tuple[float, float] = (20.0, 200.0)
    order: int = 4  # Butterworth order of both filters (run forwards and backwards)
    pre_gap_s: float = 0.2  # a_pre ends this long before the torque crossing
    peak_lead_s: float = 0.05  # the kick may start this long before the crossing (timing skew)
    final_fraction: float = 0.25
    min_prominence_ms2: float = 0.03  # an extremum counts when this prominent, 4x the noise, and ...
    relative_prominence: float = 0.04  # ... this fraction of the step from a_pre to the settled level
    max_extrema: int = 6
    min_swing_fraction: float = 0.15  # extrema after a swing smaller than this x the first are not used
    rise_fraction: float = 0.1
    pedal_fraction: float = 0.1
    pedal_min_pct: float = 1.0
    clunk_before_s: float = 0.03
    clunk_after_s: float = 0.06
    derive_cutoff_hz: float = 15.0  # low pass of the speed differentiator (app.analysis.accel)
    bandwidth_factor: float = 1.5  # a derived acceleration resolves the shuffle below bandwidth / this (gain >= 0.96)
    max_fit_error: float = 0.05  # ... and (speed-derived: kick, p-p from the fit) the fit's amplitude within this
    compare_with: str = "body"  # simulated side compared with the measurement: "body" (an ESP sensor) or "seat_rail"

    def __post_init__(self) -> None:
        lo, hi = self.clunk_band_hz
        if not (self.lowpass_hz >= 1.0 and 1.0 <= lo < hi and 1 <= self.order <= 8 and 0 < self.final_fraction <= 1
                and self.max_extrema >= 2 and self.derive_cutoff_hz >= 1.0 and self.bandwidth_factor >= 1
                and self.max_fit_error > 0 and self.compare_with in ("body", "seat_rail")):
            raise ValueError("drivability parameters: cut-offs must be at least 1 Hz (clunk band low < high), "
                             "1 <= order <= 8, 0 < final_fraction <= 1, max_extrema >= 2, bandwidth_factor >= 1, "
                             "max_fit_error > 0, compare_with 'body' or 'seat_rail'")


@dataclass(frozen=True)
class Drivability(Serial):
    """The criteria of one acceleration trace around one event (NaN where not determinable)."""

    response_delay_s: float
    kick_ms2: float
    shuffle_pp_ms2: float
    shuffle_freq_hz: float
    shuffle_damping_ratio: float
    max_jerk_ms3: float
    clunk_ms2: float
    vdv_ms175: float
    settled_accel_ms2: float
    t_kick_s: float = NAN
    t_rise_s: float = NAN
    pre_accel_ms2: float = NAN
    sample_period_s: float = NAN
    # criterion -> why it is not determinable (null) or "unresolved: ..." for a derived acceleration
    resolution: dict[str, str] = field(default_factory=dict)

    def values(self) -> dict[str, float]:
        return {k: getattr(self, k) for k in CRITERIA_NAMES}


def _rate(fs: float) -> float:
    rate = _RATES.get(fs)
    if rate is None:  # jitter in the last digits of a period must not defeat the design cache
        if len(_RATES) > 1024:
            _RATES.clear()
        rate = _RATES[fs] = float(f"{fs:.6g}")
    return rate


_RATES: dict[float, float] = {}


def _lowpass(a: FloatArray, fs: float, fc: float, order: int) -> FloatArray:
    fs = _rate(fs)
    return zero_phase(butter_sos(order, min(fc, 0.4 * fs), "low", fs), a)


def _bandpass(a: FloatArray, fs: float, lo: float, hi: float, order: int) -> FloatArray:
    fs = _rate(fs)
    return zero_phase(butter_sos(order, (lo, min(hi, 0.45 * fs)), "band", fs), a)


def _crossing(t: FloatArray, y: FloatArray, level: float, i0: int) -> float:
    """First time from index ``i0`` on where ``y`` reaches ``level`` from below (linear interpolation)."""
    above = np.nonzero(y[i0:] >= level)[0]
    if not above.size:
        return NAN
    i = i0 + int(above[0])
    if i == 0 or y[i - 1] >= level:
        return float(t[i])
    return float(t[i - 1] + (level - y[i - 1]) / (y[i] - y[i - 1]) * (t[i] - t[i - 1]))


def _sinc_vertices(y: FloatArray, idx: list[int]) -> list[tuple[float, float]]:
    """Sub-sample offset and value of the extremum of ``y`` near each index of ``idx`` from a windowed-sinc
    interpolation over +-8 samples (:func:`app.analysis.feel_kernels.sinc_refine`); the parabolic vertex at the
    edges. A maximum or a minimum as the sample and its neighbours say."""
    inner = [i for i in idx if 8 <= i <= y.size - 9]
    if len(inner) == len(idx):
        off, val = sinc_refine(y, np.array(idx, dtype=np.int64), _SINC, _OFFSETS)
        return list(zip(off.tolist(), val.tolist(), strict=True))
    return [_sinc_vertices(y, [i])[0] if 8 <= i <= y.size - 9 else parabolic_vertex(y, i) for i in idx]


def _extrema(y: FloatArray, i0: int, prominence: float) -> list[int]:
    """Alternating extrema of ``y`` from index ``i0``, starting with a maximum, each at least ``prominence``
    away from the one before (a zig-zag filter over the local extrema: a smaller reversal is passed over and
    the larger of two same-kind extrema kept). The start of the segment counts as a minimum, so the first
    maximum must rise ``prominence`` above what precedes it."""
    seg = np.ascontiguousarray(y[i0:])
    if seg.size < 3:
        return []
    return [i0 + int(k) for k in zigzag(seg, prominence)]


@dataclass(frozen=True)
class _Fit:
    """``y ~ c + amp exp(-sig tau) cos(w tau + phi)``, ``tau = t - t0``, and the relative standard error of amp."""

    c: float
    amp: float
    sig: float
    w: float
    phi: float
    amp_rel_se: float

    @property
    def freq_hz(self) -> float:
        return self.w / (2 * math.pi)

    @property
    def zeta(self) -> float:
        return self.sig / math.hypot(self.sig, self.w)

    def first_swing(self) -> tuple[float, float]:
        """The model's first peak (near tau = 0) and the valley after it, as values of y."""
        period = 2 * math.pi / self.w
        tau = np.linspace(-0.25 * period, 0.75 * period, 401)
        y = self.c + self.amp * np.exp(-self.sig * tau) * np.cos(self.w * tau + self.phi)
        k = int(np.argmax(y[:201]))
        return float(y[k]), float(np.min(y[k:k + 201]))


def _damped_fit(t: FloatArray, y: FloatArray, t0: float, c0: float, a0: float, f0: float,
                zeta0: float) -> _Fit | None:
    """The damped sine fitted by least squares from the kick peak ``t0`` on, over at most ``FIT_PERIODS``
    periods (None: no convergence inside the bounds).

    Levenberg-Marquardt with the analytic Jacobian, compiled (:func:`app.analysis.feel_kernels.damped_sine_fit`,
    some 10 us per event); where it does not converge inside the bounds (a start far from the minimum, as
    on a small kick in noise, can send its first steps elsewhere) MINPACK's trust-region variant from the
    same start, whose bounded first steps stay nearer the start, has the last word."""
    m = (t >= t0) & (t <= t0 + FIT_PERIODS / f0)  # the first periods carry the shuffle; later ones mostly noise
    if m.sum() < 8:
        return None
    tau, ym = np.ascontiguousarray(t[m] - t0), np.ascontiguousarray(y[m])
    w0 = 2 * math.pi * f0
    s0 = (zeta0 if math.isfinite(zeta0) else 0.15) * w0
    x0 = np.array([c0, a0, s0, w0, 0.0])
    status, x, cost, var_amp = damped_sine_fit(tau, ym, x0)
    fit = _accepted(x, cost, var_amp, tau.size, w0) if status == FIT_OK else None
    return fit if fit is not None else _minpack_fit(tau, ym, x0, w0)


def _accepted(x: FloatArray, cost: float, var_amp: float, n: int, w0: float) -> _Fit | None:
    """The fit of parameters ``x`` (sum of squares ``cost`` over ``n`` samples, ``(J^T J)^-1`` of the amplitude
    ``var_amp``), or None outside the bounds: frequency within 0.6-1.6 x the start, damping below 2 x it."""
    c, amp, sig, w, phi = (float(v) for v in x)
    if w < 0:
        w, phi = -w, -phi
    if not (0.6 * w0 < w < 1.6 * w0) or not 0.0 <= sig < 2.0 * w0 or amp == 0:
        return None
    var = cost / max(1, n - 5)
    rel = math.sqrt(max(var_amp * var, 0.0)) / abs(amp) if math.isfinite(var_amp) else math.inf
    return _Fit(c, amp, sig, w, phi, rel)


def _minpack_fit(tau: FloatArray, ym: FloatArray, x0: FloatArray, w0: float) -> _Fit | None:
    """:func:`_damped_fit` by MINPACK (``scipy.optimize.leastsq``, relative tolerances 1e-6)."""
    def resid(x: FloatArray) -> FloatArray:
        c, amp, sig, w, phi = x
        return np.asarray(c + amp * np.exp(-sig * tau) * np.cos(w * tau + phi) - ym, dtype=np.float64)

    def jac(x: FloatArray) -> FloatArray:
        _, amp, sig, w, phi = x
        e = np.exp(-sig * tau)
        cos, sin = np.cos(w * tau + phi), np.sin(w * tau + phi)
        return np.column_stack((np.ones_like(tau), e * cos, -amp * tau * e * cos, -amp * tau * e * sin,
                                -amp * e * sin))

    try:  # a trial step with a negative decay overflows exp; MINPACK rejects that step, the warning says nothing
        with np.errstate(over="ignore", invalid="ignore"):
            x, cov, info, _, ier = optimize.leastsq(resid, x0, Dfun=jac, full_output=True, maxfev=100, ftol=1e-6,
                                                    xtol=1e-6)
    except (ValueError, TypeError, np.linalg.LinAlgError):
        return None
    if ier not in (1, 2, 3, 4):
        return None
    var_amp = float(cov[1, 1]) if cov is not None else math.inf
    return _accepted(x, float(np.sum(info["fvec"] ** 2)), var_amp, tau.size, w0)


def pedal_move(pedal: Signal | None, t_start: float, t_cross: float, p: DrivabilityParams) -> tuple[float, str]:
    """Time (s) the pedal first moves in the event window, or NaN and why not."""
    if pedal is None or len(pedal) < 2:
        return NAN, "no pedal channel"
    w = pedal.window(t_start, t_cross + 0.3)
    ok = np.isfinite(w.values)
    t, v = w.t[ok], w.values[ok]
    if t.size < 3:
        return NAN, "too few pedal samples in the window"
    n_pre = int(np.count_nonzero(t <= t_start + 0.15))
    pre = median(np.ascontiguousarray(v[t <= t_start + 0.15])) if n_pre else float(v[0])
    step = float(v[-1] - pre)
    thr = max(p.pedal_min_pct, p.pedal_fraction * abs(step))
    moved = np.nonzero(np.abs(v - pre) >= thr)[0]
    if not moved.size or abs(step) < p.pedal_min_pct:
        return NAN, "the pedal does not move in the window (torque change without the driver)"
    i = int(moved[0])
    if i == 0:
        return float(t[0]), ""
    d0, d1 = abs(v[i - 1] - pre), abs(v[i] - pre)
    return float(t[i - 1] + (thr - d0) / (d1 - d0) * (t[i] - t[i - 1])) if d1 > d0 else float(t[i]), ""


def drivability_criteria(
    t: FloatArray, a: FloatArray, t_start: float, t_end: float, t_cross: float, direction: float,
    params: DrivabilityParams | None = None, *, pedal: Signal | None = None, t_close: float = NAN,
    bandwidth_hz: float = math.inf, shuffle_hint_hz: float = NAN, saturated: bool = False,
    noise_ms2: float = NAN, pedal_time: tuple[float, str] | None = None,
) -> Drivability:
    """The criteria (module docstring) of uniform samples ``t`` (s), ``a`` (m/s^2), shape (n,) each.

    ``t``/``a`` may extend beyond ``[t_start, t_end]`` (filter run-in); the criteria use the window.
    ``bandwidth_hz`` is the bandwidth of an acceleration derived from speed (inf: an accelerometer);
    ``shuffle_hint_hz`` the shuffle frequency known from the motor speed, to judge that bandwidth;
    ``pedal_time`` the pedal's first move (:func:`pedal_move`) when already known (then ``pedal`` is not read);
    ``noise_ms2`` the noise such a derivation leaves (finite: kick and peak-to-peak are read off the fitted
    damped sine, unresolved when its amplitude's standard error exceeds ``max_fit_error``).
    """
    p = params or DrivabilityParams()
    nan_all = Drivability(NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN, NAN)
    ok = np.isfinite(a)
    if t.size < 8 or ok.sum() < 8:
        return _with(nan_all, {k: "fewer than 8 acceleration samples in the window" for k in CRITERIA_NAMES})
    if not ok.all():
        a = np.interp(t, t[ok], a[ok])
    dt = float((t[-1] - t[0]) / (t.size - 1))
    fs = 1.0 / dt
    reasons: dict[str, str] = {}
    lp = _lowpass(a, fs, p.lowpass_hz, p.order)
    inside = (t >= t_start) & (t <= t_end)
    iw = np.nonzero(inside)[0]
    if iw.size < 8:
        return _with(nan_all, {k: "the acceleration does not cover the event window" for k in CRITERIA_NAMES})
    i_a, i_b = int(iw[0]), int(iw[-1]) + 1
    noise = residual_rms(a[i_a:i_b], lp[i_a:i_b])
    tw, lw = t[i_a:i_b], lp[i_a:i_b]
    pre_m = tw <= t_cross - p.pre_gap_s
    a_pre = median(lw[pre_m]) if pre_m.any() else float(lw[0])
    n_final = max(2, round(p.final_fraction * tw.size))
    a_set = median(np.ascontiguousarray(lw[-n_final:]))
    y = direction * lw
    prom = max(p.min_prominence_ms2, 4.0 * noise, p.relative_prominence * abs(a_set - a_pre))
    i0 = int(np.searchsorted(tw, t_cross - p.peak_lead_s))
    ext = _extrema(y, i0, prom)
    kick = pp = freq = zeta = t_kick = t_rise = NAN
    if not ext:
        reasons["kick_ms2"] = reasons["shuffle_pp_ms2"] = "no acceleration peak after the torque crossing"
    else:
        # a 100 Hz trace has 12 samples per cycle of an 8 Hz shuffle, too few for a parabolic vertex within 1 %:
        # below REFINE_BELOW_HZ each extremum is refined on a band-limited (windowed-sinc) interpolation
        verts = (_sinc_vertices(y, ext[: p.max_extrema]) if fs < REFINE_BELOW_HZ
                 else [parabolic_vertex(y, i) for i in ext[: p.max_extrema]])
        times = np.array([tw[i] + off * dt for i, (off, _) in zip(ext, verts, strict=False)])
        vals = np.array([v for _, v in verts])
        swings = np.abs(vals[1:] - vals[:-1])
        if swings.size:  # later swings drowned in noise would bias the frequency and the decay
            keep = int(np.argmax(np.concatenate((swings < p.min_swing_fraction * swings[0], [True]))))
            times, vals = times[: keep + 1], vals[: keep + 1]
        t_kick = float(times[0])
        kick = float(vals[0] - direction * a_set)
        swings = np.abs(vals[1:] - vals[:-1])
        if swings.size:
            pp = float(swings.max())
        else:
            reasons["shuffle_pp_ms2"] = "no swing after the kick peak"
        if times.size >= 2:
            freq = float(1.0 / (2.0 * np.mean(times[1:] - times[:-1])))
        else:
            reasons["shuffle_freq_hz"] = "fewer than two extrema"
        if swings.size >= 2 and (swings > 0).all():
            n_sw = np.arange(swings.size) - 0.5 * (swings.size - 1)
            slope = float(np.dot(n_sw, np.log(swings)) / np.dot(n_sw, n_sw))  # least-squares slope of ln(swing) over k
            delta = -2.0 * slope
            zeta = float(delta / math.sqrt(4 * math.pi**2 + delta**2)) if delta > 0 else NAN
            if not math.isfinite(zeta):
                reasons["shuffle_damping_ratio"] = "the swings do not decay"
        else:
            reasons["shuffle_damping_ratio"] = "fewer than two swings"
        if math.isfinite(freq):
            # the motor speed's shuffle frequency, when known, is the better starting point: a small kick in
            # noise can put the extrema (and a fit started there) on the wrong period
            f_start = shuffle_hint_hz if math.isfinite(shuffle_hint_hz) and shuffle_hint_hz > 0 else freq
            fitted = _damped_fit(t[i_a:i_b], direction * lp[i_a:i_b], t_kick, direction * a_set,
                                 float(vals[0]) - direction * a_set, f_start, zeta)
            if fitted is not None:
                freq, zeta, level = fitted.freq_hz, fitted.zeta, fitted.c
                reasons.pop("shuffle_damping_ratio", None)
                a_set = direction * level  # the oscillation's own centre: exact while it has not died out
                kick = float(vals[0] - level)
                if math.isfinite(noise_ms2):  # derived from speed: read the swing off the fit, not the noisy peaks
                    peak, valley = fitted.first_swing()
                    kick, pp = peak - level, peak - valley
                    if fitted.amp_rel_se > p.max_fit_error:
                        why = (f"unresolved: the shuffle amplitude is known to {fitted.amp_rel_se * 100:.0f} % only "
                               f"(noise {noise_ms2:.3f} m/s^2 RMS on the acceleration derived from speed)")
                        reasons.setdefault("kick_ms2", why)
                        reasons.setdefault("shuffle_pp_ms2", why)
            elif math.isfinite(noise_ms2):
                reasons.setdefault("shuffle_pp_ms2", "unresolved: no damped oscillation fits the acceleration "
                                                     "derived from speed")
                reasons.setdefault("kick_ms2", reasons["shuffle_pp_ms2"])
        height = float(vals[0] - direction * a_pre)
        if height > 0:
            t_rise = _crossing(tw, y, direction * a_pre + p.rise_fraction * height, i0)
    # max |d a_lp / dt| over the window from i0 (np.gradient's differences: central, one-sided at lp's ends)
    max_jerk = max_abs_slope(lp, dt, i_a + i0, i_b) if i0 < i_b - i_a else NAN
    lo, hi = p.clunk_band_hz
    clunk = NAN
    if lo >= 0.9 * 0.45 * fs:
        reasons["clunk_ms2"] = f"the sampling ({fs:.0f} Hz) cannot carry the clunk band above {lo:g} Hz"
    else:
        t_c = t_close if math.isfinite(t_close) else t_rise
        if not math.isfinite(t_c):
            reasons["clunk_ms2"] = "no lash closure time and no acceleration rise"
        else:
            near = (t >= t_c - p.clunk_before_s - CLUNK_PAD_S) & (t <= t_c + p.clunk_after_s + CLUNK_PAD_S)
            tn = t[near]
            hf = _bandpass(a[near], fs, lo, hi, p.order) if tn.size > 8 else np.full(tn.size, NAN)
            m = (tn >= t_c - p.clunk_before_s) & (tn <= t_c + p.clunk_after_s)
            clunk = float(np.max(np.abs(hf[m]))) if m.any() else NAN
    dose = vdv(a[i_a:i_b], fs)
    t_pedal, why = pedal_time if pedal_time is not None else pedal_move(pedal, t_start, t_cross, p)
    delay = t_rise - t_pedal if math.isfinite(t_pedal) and math.isfinite(t_rise) else NAN
    if why:
        reasons["response_delay_s"] = why
    elif not math.isfinite(delay):
        reasons["response_delay_s"] = "no acceleration rise"
    out = Drivability(delay, kick, pp, freq, zeta, max_jerk, clunk, dose, a_set, t_kick, t_rise, a_pre, dt)
    if saturated:
        for k in ("kick_ms2", "shuffle_pp_ms2", "max_jerk_ms3", "clunk_ms2", "vdv_ms175"):
            reasons[k] = "the accelerometer is saturated in this window"
    if math.isfinite(bandwidth_hz):
        f_ref = shuffle_hint_hz if math.isfinite(shuffle_hint_hz) else freq
        if math.isfinite(f_ref) and bandwidth_hz < p.bandwidth_factor * f_ref:
            why = (f"unresolved: acceleration derived from speed with bandwidth {bandwidth_hz:.1f} Hz, below "
                   f"{p.bandwidth_factor:g} x the shuffle frequency {f_ref:.1f} Hz")
            for k in ("kick_ms2", "shuffle_pp_ms2", "shuffle_damping_ratio", "max_jerk_ms3"):
                reasons.setdefault(k, why)
        reasons.setdefault("clunk_ms2", f"unresolved: an acceleration derived from speed ({bandwidth_hz:.1f} Hz "
                                        "bandwidth) carries no clunk")
    return _with(out, reasons)


def _with(d: Drivability, reasons: dict[str, str]) -> Drivability:
    """``d`` with the criteria named in ``reasons`` set to NaN (a reason marks the value as not supported)."""
    values = dict(d.__dict__)  # dataclasses.replace, without its per-call field checks
    values.update({k: NAN for k in reasons if k in CRITERIA}, resolution=dict(reasons))
    return Drivability(**values)


def difference(measured: Drivability, simulated: Drivability) -> dict[str, float]:
    """``simulated - measured`` per criterion (NaN if either is)."""
    m, s = measured.values(), simulated.values()
    return {k: s[k] - m[k] for k in CRITERIA_NAMES}
