"""What the torque channel cannot tell: prediction variance no candidate effect should be asked to remove.

The diagnosis drives the simulator with the *logged* torque. Where that record is imperfect, the
prediction is uncertain by an amount computed from the torque samples and the model alone -- never
from the measured speed, so none of these terms can absorb a real gap. Each is a per-sample
variance (rpm^2) added to the speed noise of :mod:`.noise`:

- **reconstruction** between samples (:func:`input_uncertainty`): the prediction with monotone
  cubics and with straight lines through the samples differ by what the sample rate hides;
- **white noise on the torque samples** (:func:`torque_noise_variance`): an inverter's torque
  estimate carries noise the air-gap torque does not have; fed to the simulator it makes the model
  ring (a 0.3 N m noise on a 100 Hz torque gave about 2 rpm RMS on the paper vehicle, over 3x the speed noise,
  on drives whose model was otherwise exact). Propagated by Monte Carlo through the fitted baseline;
- **quantisation of held values** (:func:`torque_quantisation_variance`): one rounding error acting
  for as long as the value is held, integrated by the vehicle inertia;
- optionally a **model-form tolerance** (``form_rel`` of :func:`input_uncertainty`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from app.analysis.diagnosis.calibrate import FitResult
from app.analysis.diagnosis.forward import (
    DiagEvent,
    EffectSetting,
    FloatArray,
    Nuisance,
    SimOut,
    simulate_events,
    vehicle_with,
)
from app.analysis.diagnosis.noise import NoiseFloor
from sim import Vehicle

FORM_WINDOW_S = 0.15  # s: local window of the model-form tolerance (about one shuffle period)
NOISE_DRAWS = 6  # Monte Carlo draws of the torque noise (the variance is then averaged over SMOOTH_S too)
SMOOTH_S = 0.05  # s: local averaging of the squared prediction differences


def _moving_mean(x: FloatArray, k: int) -> FloatArray:
    """Centred moving mean over ``k`` samples; the ends are padded by odd reflection, so a straight line
    (a speed ramp under steady torque) is its own moving mean up to the ends."""
    if k <= 1 or x.size < k:
        return np.asarray(x, dtype=np.float64)
    lo, hi = k // 2, k - 1 - k // 2
    pad = np.concatenate((2.0 * x[0] - x[lo:0:-1], x, 2.0 * x[-1] - x[-2:-2 - hi:-1]))
    return np.asarray(np.convolve(pad, np.ones(k) / k, mode="valid"), dtype=np.float64)


def input_uncertainty(events: Sequence[DiagEvent], vehicle: Vehicle, nuisance: Nuisance,
                      effects: Sequence[EffectSetting] = (), model: str = "multibody",
                      smooth_s: float = SMOOTH_S, form_rel: float = 0.0,
                      reference: Sequence[SimOut] | None = None) -> list[FloatArray]:
    """Per event, (n,) variance (rpm^2) of the prediction that no candidate effect should be asked to remove.

    Two parts. **Input reconstruction**: the prediction is made twice, with the torque filled in by
    monotone cubics and by straight lines; their squared difference, averaged over ``smooth_s``, is
    the part of the residual no driveline model can remove at this sample rate. **Model form**
    (``form_rel`` > 0): two sound models of the same driveline -- other contact laws, a split
    differential, a relaxation tyre -- differ by a few per cent of the transient they predict
    (``docs/diagnosis.md``, independent generator), so each sample also gets the variance of
    ``form_rel`` times the local RMS (over ``FORM_WINDOW_S``) of the event's simulated oscillation (the
    prediction less its moving mean over that window). A residual below that is no evidence of a
    missing effect; where the model predicts a quiet stretch the full sensor-noise weight stays. Both parts use
    the torque and the model only, never the measured speed, so they cannot absorb a gap.
    ``reference``: the monotone-cubic run of these events and settings, when the caller already has it.
    """
    a_all = reference if reference is not None else simulate_events(events, vehicle, nuisance.gain, effects,
                                                                     model, "pchip")
    b_all = simulate_events(events, vehicle, nuisance.gain, effects, model, "linear")
    out: list[FloatArray] = []
    for ev, a_out, b_out in zip(events, a_all, b_all, strict=True):
        a = a_out.at(ev.speed_t, nuisance.offset_s)
        var = _local_mean_square(ev, a - b_out.at(ev.speed_t, nuisance.offset_s), smooth_s)
        if form_rel > 0.0 and ev.n >= 3:
            dt = max(float(np.median(np.diff(ev.speed_t))), 1e-4)
            # the predicted oscillation: the prediction less its moving average over about one shuffle period
            # (the rigid-body trend, however it bends at the reversal), then its local mean square: amplitude
            # and phase errors of a sound model scale with the swing it predicts there, and a stretch where it
            # predicts none (a quiet pre-event, a settled tail) keeps its full sensor-noise weight
            kf = max(round(FORM_WINDOW_S / dt), 1)
            dyn = a - _moving_mean(a, kf)
            var = var + form_rel**2 * _moving_mean(dyn * dyn, kf)
        out.append(np.asarray(var, dtype=np.float64))
    return out


def rigid_inertia(vehicle: Vehicle) -> float:
    """Inertia of the whole driveline and vehicle as one rigid body, referred to the rotor (kg m^2)."""
    m = vehicle.compiled
    return float(np.sum(m.inertia * m.speed_ratio**2))


def torque_quantisation_variance(ev: DiagEvent, step_nm: float, inertia: float) -> FloatArray:
    """(n,) speed variance (rpm^2) from the quantisation of the CAN torque.

    While the torque is held, consecutive CAN values are equal and all carry the *same* rounding
    error ``d`` (uniform, variance ``step^2 / 12``); the vehicle inertia integrates it into a speed
    drift ``d (t - t_0) / J`` that grows through the window. Samples are grouped into runs of equal
    values, each run with its own independent error acting over the run's time (half-way to the
    neighbouring samples); the drift is taken relative to its mean on the anchor samples, which the
    per-event speed anchor removes. A torque that moves (ramps, or dithered by noise) makes short
    runs, and the term stays small. It uses the torque samples and the vehicle only.
    """
    n = ev.n
    if step_nm <= 0 or ev.torque_t.size < 2 or inertia <= 0:
        return np.zeros(n)
    tt, vv = ev.torque_t, ev.torque_nm
    edges = np.concatenate([[tt[0] - 0.5 * (tt[1] - tt[0])], 0.5 * (tt[1:] + tt[:-1]),
                            [tt[-1] + 0.5 * (tt[-1] - tt[-2])]])
    # the samples of one run act over consecutive intervals, so a run acts from its first sample's start edge
    # (not before the simulation start) to its last sample's end edge: (n, runs), not (n, samples)
    first = np.flatnonzero(np.concatenate([[True], np.diff(vv) != 0]))
    last = np.concatenate([first[1:] - 1, [vv.size - 1]])
    start = np.maximum(edges[first], ev.t_fine[0])
    end = edges[last + 1]
    # run r has acted for p(s) = clip(min(end_r, s) - start_r, 0) by sample time s: its whole length once it has
    # ended, s - start_r while it is held, 0 before; less its mean m_r over the anchor samples. The sum over runs of
    # (p - m)^2 is then a prefix sum over the ended runs, the held run's term and a suffix sum over the runs to come
    # (the runs follow each other: at most one is held at any time), O(samples + runs) instead of a
    # (samples, runs) matrix (1300 x 5000 for a 1 kHz window)
    length = np.clip(end - start, 0.0, None)
    m = _anchor_means(ev.speed_t[ev.pre], start, end) if ev.pre.any() else np.zeros(first.size)
    done = np.concatenate([[0.0], np.cumsum((length - m) ** 2)])
    to_come = np.concatenate([np.cumsum((m**2)[::-1])[::-1], [0.0]])
    s = ev.speed_t
    k = np.searchsorted(end, s, side="right")  # runs ended by s (end increases run by run)
    held = k < first.size
    kk = np.minimum(k, first.size - 1)
    q = np.where(held, np.clip(s - start[kk], 0.0, None), 0.0)
    total = done[k] + np.where(held, (q - m[kk]) ** 2 + to_come[np.minimum(k + 1, first.size)], 0.0)
    rpm_per_nm_s = 30.0 / np.pi / inertia
    return np.asarray(step_nm**2 / 12.0 * rpm_per_nm_s**2 * total, dtype=np.float64)


def _anchor_means(s: FloatArray, start: FloatArray, end: FloatArray) -> FloatArray:
    """Per run, the mean over the anchor sample times ``s`` of the time it has acted, clip(min(end, s) - start, 0)."""
    s = np.sort(s)
    cum = np.concatenate([[0.0], np.cumsum(s)])
    length = np.clip(end - start, 0.0, None)
    a = np.searchsorted(s, start, side="left")  # samples before the run starts: 0
    b = np.searchsorted(s, np.maximum(end, start), side="left")  # samples after it ended: its whole length
    acting = (cum[b] - cum[a]) - (b - a) * start  # samples while it is held: s - start
    return np.asarray((acting + (s.size - b) * length) / s.size, dtype=np.float64)


def _local_mean_square(ev: DiagEvent, d: FloatArray, smooth_s: float) -> FloatArray:
    """Mean of ``d^2`` over ``smooth_s`` around each sample, after removing its mean on the anchor samples
    (the per-event speed anchor removes any level)."""
    if ev.pre.any():
        d = d - float(np.mean(d[ev.pre]))
    dt = max(float(np.median(np.diff(ev.speed_t))), 1e-4) if ev.n > 1 else smooth_s
    k = max(round(smooth_s / dt), 1)
    return np.asarray(np.convolve(d * d, np.ones(k) / k, mode="same"), dtype=np.float64)


def torque_noise_variance(events: Sequence[DiagEvent], vehicle: Vehicle, nuisance: Nuisance, sigma_nm: float,
                          model: str = "multibody", draws: int = NOISE_DRAWS, seed: int = 0,
                          smooth_s: float = SMOOTH_S, reference: Sequence[SimOut] | None = None) -> list[FloatArray]:
    """Per event, (n,) variance (rpm^2) of the prediction caused by white noise of ``sigma_nm`` (N m) on the
    torque samples.

    The noise actually present in the log is one draw the simulator cannot tell from torque; its effect
    on the prediction is estimated by adding ``draws`` further independent draws of the same size to the
    samples and taking the mean square change of the prediction, averaged over ``smooth_s``. It costs
    ``draws`` simulator passes over the events, once per diagnosis (one more without ``reference``, the
    baseline's run of the events as they are).
    """
    if sigma_nm <= 0.0 or draws <= 0 or not events:
        return [np.zeros(ev.n) for ev in events]
    runs = reference if reference is not None else simulate_events(events, vehicle, nuisance.gain, (), model)
    ref = [r.at(ev.speed_t, nuisance.offset_s) for ev, r in zip(events, runs, strict=True)]
    rng = np.random.default_rng(seed)
    acc = [np.zeros(ev.n) for ev in events]
    for _ in range(draws):
        noisy = [replace(ev, torque_nm=ev.torque_nm + rng.normal(0.0, sigma_nm, ev.torque_nm.size)) for ev in events]
        outs = simulate_events(noisy, vehicle, nuisance.gain, (), model)
        for a, ev, o, r in zip(acc, events, outs, ref, strict=True):
            a += _local_mean_square(ev, o.at(ev.speed_t, nuisance.offset_s) - r, smooth_s)
    return [a / draws for a in acc]


def with_input_uncertainty(events: Sequence[DiagEvent], vehicle: Vehicle, fitted: FitResult, model: str,
                           noise: NoiseFloor | None = None, form_rel: float = 0.0, seed: int = 0) -> list[DiagEvent]:
    """Events whose sample variances include every term of the module docstring, evaluated with the fitted
    baseline (``noise`` gives the torque channel's quantisation step and white-noise sigma)."""
    veh = vehicle_with(vehicle, fitted.nuisance, ())
    inertia = rigid_inertia(vehicle)
    step = noise.torque_step_nm if noise is not None else 0.0
    sigma = noise.torque_sigma_nm if noise is not None else 0.0
    baseline = simulate_events(events, veh, fitted.nuisance.gain, (), model)  # one run serves both terms
    extra = input_uncertainty(events, veh, fitted.nuisance, (), model, form_rel=form_rel, reference=baseline)
    white = torque_noise_variance(events, veh, fitted.nuisance, sigma, model, seed=seed, reference=baseline)
    return [replace(ev, var=ev.var + u + w + torque_quantisation_variance(ev, step, inertia))
            for ev, u, w in zip(events, extra, white, strict=True)]
