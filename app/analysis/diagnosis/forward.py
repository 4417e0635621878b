"""Event data and the forward model: measured torque of one event -> predicted measured speed.

Only the event windows are simulated. For one event and one parameter set the prediction is::

    torque_in(t)  = gain * T_can(t) + input effects                   (1 ms grid, monotone cubic)
    speed_sim     = simulate(vehicle + vehicle effects, torque_in, speed0 = measured speed at start)
    speed_pred(t) = output effects(speed_sim)(t - offset) + c_e       at the measured sample times

``offset`` (s; positive: the speed reacts later than the CAN torque timestamps say), ``gain`` and
the road load (``body.grade_percent`` offset, a wheel-side force) are the *nuisance* parameters
fitted in every fit. Because the driveline is time-invariant, delaying the input by ``offset``
delays the output by the same amount, so one simulation serves every offset: the offset is
profiled out by shifting the simulated output (see :func:`best_offset`), exactly and cheaply.
``c_e`` is a per-event speed offset solved in closed form on the pre-event samples only: the
simulator starts from one noisy speed sample, and this re-anchors the initial condition without
touching the transient.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import PchipInterpolator

from sim import Vehicle, simulate
from sim.effects.base import Effect
from sim.model import build_chain

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

FINE_DT = 0.001  # s: grid of the simulated torque input and output
MARGIN_S = 0.03  # s: simulated beyond the window so the output can be shifted by the offset


@dataclass(frozen=True)
class DiagEvent:
    """Measured data of one event window (times in s since measurement start).

    Attributes
    ----------
    index, kind : event index and ``"tip_in"`` / ``"tip_out"``.
    t_event : torque zero crossing.
    t_start, t_end : window scored.
    speed_rpm, torque_step_nm : stratification keys (speed at the crossing, torque after - before).
    torque_t, torque_nm : (m,) CAN torque samples covering the window with some margin.
    speed_t, speed_meas : (n,) measured speed samples inside the window.
    var : (n,) noise variance of each speed sample (rpm^2).
    pre : (n,) mask of samples before the event (initial-condition anchor).
    """

    index: int
    kind: str
    t_event: float
    t_start: float
    t_end: float
    speed_rpm: float
    torque_step_nm: float
    torque_t: FloatArray
    torque_nm: FloatArray
    speed_t: FloatArray
    speed_meas: FloatArray
    var: FloatArray
    pre: BoolArray
    t_fine: FloatArray = field(init=False, repr=False)
    torque_fn: PchipInterpolator = field(init=False, repr=False)

    def __post_init__(self) -> None:
        t0 = max(self.t_start - MARGIN_S, float(self.torque_t[0]))
        n = round((self.t_end + MARGIN_S - t0) / FINE_DT) + 1
        object.__setattr__(self, "t_fine", t0 + FINE_DT * np.arange(n, dtype=np.float64))
        # monotone cubic: follows a smooth torque request through its samples without overshoot, where
        # straight lines would cut the corners of every ramp by up to half a CAN period
        object.__setattr__(self, "torque_fn", PchipInterpolator(self.torque_t, self.torque_nm, extrapolate=False))

    @property
    def n(self) -> int:
        return int(self.speed_t.size)

    def speed0(self) -> float:
        """Measured speed at the simulation start: a line through the first 50 ms of samples."""
        m = self.speed_t <= self.speed_t[0] + 0.05
        if int(m.sum()) < 3:
            return float(self.speed_meas[0])
        c = np.polyfit(self.speed_t[m] - self.speed_t[0], self.speed_meas[m], 1)
        return float(np.polyval(c, self.t_fine[0] - self.speed_t[0]))


@dataclass(frozen=True)
class Nuisance:
    """Nuisance parameters: torque-speed time offset (s), torque gain (-), road load (grade %)."""

    offset_s: float = 0.0
    gain: float = 1.0
    grade_pct: float = 0.0

    def to_dict(self) -> dict[str, float]:
        return {"offset_s": self.offset_s, "gain": self.gain, "road_load_grade_pct": self.grade_pct}


EffectSetting = tuple[Effect, Mapping[str, float]]


@dataclass(frozen=True)
class SimOut:
    """Simulated measured speed of one event on the fine grid, before the offset shift.

    Attributes
    ----------
    t, speed : (m,) s and rpm.
    gap_open : (m,) any backlash open, or None when the simulator does not say.
    """

    t: FloatArray
    speed: FloatArray
    gap_open: BoolArray | None

    def at(self, t: FloatArray, offset_s: float) -> FloatArray:
        return np.asarray(np.interp(t - offset_s, self.t, self.speed), dtype=np.float64)


@dataclass(frozen=True)
class Prediction:
    """Predicted speed of one event.

    Attributes
    ----------
    speed : (n,) prediction at ``DiagEvent.speed_t`` including offset and anchor (rpm).
    t_fine, speed_fine : simulated output on the fine grid, already shifted by the offset (rpm).
    gap_open : (len(t_fine),) any backlash open (shifted), or None.
    anchor_rpm : the closed-form initial-condition offset ``c_e``.
    """

    speed: FloatArray
    t_fine: FloatArray
    speed_fine: FloatArray
    gap_open: BoolArray | None
    anchor_rpm: float


def vehicle_with(base: Vehicle, nuisance: Nuisance, effects: Sequence[EffectSetting]) -> Vehicle:
    """The base vehicle with the road-load nuisance and every effect's field changes, in one rebuild."""
    changes: dict[str, Any] = {}
    if nuisance.grade_pct != 0.0:
        changes["body.grade_percent"] = base.body.grade_percent + nuisance.grade_pct
    for eff, vals in effects:
        if eff.vehicle_change is not None:
            changes.update(eff.vehicle_change(base, vals))
    return base.with_changes(changes) if changes else base


def torque_input(ev: DiagEvent, gain: float, effects: Sequence[EffectSetting], interp: str = "pchip") -> FloatArray:
    """Torque on the fine grid after gain and input effects (N m); ``interp``: "pchip" or "linear"."""
    tq_t = np.clip(ev.t_fine, ev.torque_t[0], ev.torque_t[-1])
    raw = ev.torque_fn(tq_t) if interp == "pchip" else np.interp(tq_t, ev.torque_t, ev.torque_nm)
    tq = gain * raw
    for eff, vals in effects:
        if eff.input_transform is not None:
            tq = eff.input_transform(ev.t_fine, tq, vals)
    return np.asarray(tq, dtype=np.float64)


def _gap_any(res: Any, n: int) -> BoolArray | None:
    """Any backlash open at each output sample (the simulator reports one mask per gap)."""
    g = getattr(res, "gap_open", None)
    if not g:
        return None
    masks = [np.asarray(m, dtype=bool) for m in (g.values() if isinstance(g, Mapping) else [g])]
    masks = [m for m in masks if m.shape == (n,)]
    return np.logical_or.reduce(masks) if masks else None


def simulate_event(ev: DiagEvent, vehicle: Vehicle, gain: float, effects: Sequence[EffectSetting] = (),
                   model: str = "multibody", interp: str = "pchip") -> SimOut:
    """One simulator run over the event's fine grid; ``vehicle`` already carries the vehicle effects."""
    tq = torque_input(ev, gain, effects, interp)
    res = simulate(vehicle, ev.t_fine, tq, model=model, speed0_rpm=ev.speed0(), interp="linear",
                   output_dt=FINE_DT)
    t_out = np.asarray(res.t, dtype=np.float64)
    sp = np.asarray(res.motor_speed_rpm, dtype=np.float64)
    for eff, vals in effects:
        if eff.output_transform is not None:
            sp = eff.output_transform(t_out, sp, vals)
    return SimOut(t_out, sp, _gap_any(res, t_out.size))


def anchored(ev: DiagEvent, raw: FloatArray) -> tuple[FloatArray, float]:
    """Prediction plus the closed-form anchor (weighted mean pre-event residual)."""
    if not ev.pre.any():
        return raw, 0.0
    w = 1.0 / ev.var[ev.pre]
    c = float(np.sum(w * (ev.speed_meas[ev.pre] - raw[ev.pre])) / np.sum(w))
    return raw + c, c


def shifted_chi2(events: Sequence[DiagEvent], outs: Sequence[SimOut], offsets: FloatArray) -> FloatArray:
    """(k,) total weighted SSE over ``events`` for each candidate offset (s)."""
    total = np.zeros(offsets.size)
    for ev, out in zip(events, outs, strict=True):
        tq = ev.speed_t[None, :] - offsets[:, None]
        raw = np.interp(tq.ravel(), out.t, out.speed).reshape(tq.shape)
        r = ev.speed_meas[None, :] - raw
        w = 1.0 / ev.var
        if ev.pre.any():
            wp = w[ev.pre]
            r = r - (r[:, ev.pre] @ wp / wp.sum())[:, None]
        total += (r * r) @ w
    return total


def best_offset(events: Sequence[DiagEvent], outs: Sequence[SimOut], bounds: tuple[float, float],
                step: float = 0.0005) -> float:
    """Offset (s) within ``bounds`` minimising the total weighted SSE: grid, then a parabola."""
    grid = np.arange(bounds[0], bounds[1] + step / 2, step)
    chi = shifted_chi2(events, outs, grid)
    k = int(np.argmin(chi))
    if 0 < k < grid.size - 1:
        a, b, c = chi[k - 1], chi[k], chi[k + 1]
        den = a - 2 * b + c
        if den > 0:
            return float(np.clip(grid[k] + 0.5 * step * (a - c) / den, bounds[0], bounds[1]))
    return float(grid[k])


def prediction(ev: DiagEvent, out: SimOut, offset_s: float) -> Prediction:
    """The anchored prediction of one event for a given offset."""
    speed, c = anchored(ev, out.at(ev.speed_t, offset_s))
    t_sh = out.t + offset_s
    return Prediction(speed, t_sh, out.speed, out.gap_open, c)


def predict(ev: DiagEvent, vehicle: Vehicle, nuisance: Nuisance, effects: Sequence[EffectSetting] = (),
            model: str = "multibody", interp: str = "pchip") -> Prediction:
    """Predicted measured speed of one event for fixed nuisance values.

    Parameters
    ----------
    ev : the event.
    vehicle : base vehicle with :func:`vehicle_with` applied.
    nuisance : nuisance parameters (the road load is already in ``vehicle``).
    effects : all effect settings (input and output transforms are applied here).
    model : simulator model name.
    interp : how the CAN torque is filled in between samples ("pchip" or "linear").
    """
    return prediction(ev, simulate_event(ev, vehicle, nuisance.gain, effects, model, interp), nuisance.offset_s)


def weighted_residual(ev: DiagEvent, pred: Prediction) -> FloatArray:
    """(n,) residual in noise units: ``(measured - predicted) / sqrt(var)``."""
    return np.asarray((ev.speed_meas - pred.speed) / np.sqrt(ev.var), dtype=np.float64)


def input_uncertainty(ev: DiagEvent, vehicle: Vehicle, nuisance: Nuisance, effects: Sequence[EffectSetting] = (),
                      model: str = "multibody", smooth_s: float = 0.05) -> FloatArray:
    """(n,) variance (rpm^2) of the prediction due to not knowing the torque between CAN samples.

    The prediction is made twice, with the torque filled in by monotone cubics and by straight
    lines; their squared difference, averaged over ``smooth_s``, is the part of the residual no
    driveline model can remove at this sample rate. It uses the torque only, never the measured
    speed, so it cannot absorb a gap.
    """
    a = simulate_event(ev, vehicle, nuisance.gain, effects, model, "pchip").at(ev.speed_t, nuisance.offset_s)
    b = simulate_event(ev, vehicle, nuisance.gain, effects, model, "linear").at(ev.speed_t, nuisance.offset_s)
    d = a - b
    if ev.pre.any():
        d = d - float(np.mean(d[ev.pre]))
    k = max(round(smooth_s / max(float(np.median(np.diff(ev.speed_t))), 1e-4)), 1)
    return np.asarray(np.convolve(d * d, np.ones(k) / k, mode="same"), dtype=np.float64)


def rigid_inertia(vehicle: Vehicle) -> float:
    """Inertia of the whole driveline and vehicle as one rigid body, referred to the rotor (kg m^2)."""
    m = build_chain(vehicle)
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
    run = np.concatenate([[0], np.cumsum(np.diff(vv) != 0)])
    lo = np.maximum(edges[:-1], ev.t_fine[0])
    # time each torque sample has acted between the simulation start and each speed sample: (n, m)
    acted = np.clip(np.minimum(edges[1:][None, :], ev.speed_t[:, None]) - lo[None, :], 0.0, None)
    per_run = np.zeros((n, int(run[-1]) + 1))
    np.add.at(per_run.T, run, acted.T)
    if ev.pre.any():
        per_run -= per_run[ev.pre].mean(axis=0)
    rpm_per_nm_s = 30.0 / np.pi / inertia
    return np.asarray(step_nm**2 / 12.0 * rpm_per_nm_s**2 * np.sum(per_run**2, axis=1), dtype=np.float64)
