"""Event data and the forward model: measured torque of one event -> predicted measured speed.

Only the event windows are simulated. For one event and one parameter set the prediction is::

    torque_in(t) = gain * T_can(t - offset) + input effects          (1 ms grid, linear)
    speed_sim    = simulate(vehicle + vehicle effects, torque_in, speed0 = measured speed at start)
    speed_pred   = output effects(speed_sim) at the measured sample times + c_e

``offset`` (s, positive: the speed reacts later than the CAN torque says), ``gain`` and the road
load (``body.grade_percent`` offset, a wheel-side force) are the *nuisance* parameters fitted in
every fit. ``c_e`` is a per-event speed offset solved in closed form on the pre-event samples
only: the simulator starts from one noisy speed sample, and this re-anchors the initial condition
without touching the transient.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from sim import Vehicle, simulate
from sim.effects.base import Effect

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

FINE_DT = 0.001  # s: grid of the simulated torque input and output


@dataclass(frozen=True)
class DiagEvent:
    """Measured data of one event window (times in s since measurement start).

    Attributes
    ----------
    index, kind : event index and ``"tip_in"`` / ``"tip_out"``.
    t_event : torque zero crossing.
    t_start, t_end : window simulated and scored.
    speed_rpm, torque_step_nm : stratification keys (speed at the crossing, torque after - before).
    torque_t, torque_nm : (m,) CAN torque samples covering the window with some margin.
    speed_t, speed_meas : (n,) measured speed samples inside the window.
    var : (n,) model-free noise variance of each speed sample (rpm^2).
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

    def __post_init__(self) -> None:
        n = int(round((self.t_end - self.t_start) / FINE_DT)) + 1
        object.__setattr__(self, "t_fine", self.t_start + FINE_DT * np.arange(n, dtype=np.float64))

    @property
    def n(self) -> int:
        return int(self.speed_t.size)

    def speed0(self) -> float:
        """Measured speed at the window start: mean of the samples within 25 ms of it."""
        m = self.speed_t <= self.speed_t[0] + 0.025
        return float(np.mean(self.speed_meas[m]))


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
class Prediction:
    """Predicted speed of one event.

    Attributes
    ----------
    speed : (n,) prediction at ``DiagEvent.speed_t`` including the anchor (rpm).
    t_fine, speed_fine : simulated output on the 1 ms grid (rpm, before the anchor).
    gap_open : (len(t_fine),) any backlash open, or None when the simulator does not say.
    anchor_rpm : the closed-form initial-condition offset ``c_e``.
    """

    speed: FloatArray
    t_fine: FloatArray
    speed_fine: FloatArray
    gap_open: BoolArray | None
    anchor_rpm: float


def vehicle_with(base: Vehicle, nuisance: Nuisance, effects: Sequence[EffectSetting]) -> Vehicle:
    """The base vehicle with the road-load nuisance and every effect's vehicle changes applied."""
    v = base
    if nuisance.grade_pct != 0.0:
        v = v.with_changes({"body.grade_percent": base.body.grade_percent + nuisance.grade_pct})
    for eff, vals in effects:
        if eff.vehicle_change is not None:
            v = eff.vehicle_change(v, vals)
    return v


def torque_input(ev: DiagEvent, nuisance: Nuisance, effects: Sequence[EffectSetting]) -> FloatArray:
    """Torque on the 1 ms grid after nuisance and input effects (N m)."""
    tq = nuisance.gain * np.interp(ev.t_fine - nuisance.offset_s, ev.torque_t, ev.torque_nm)
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


def predict(
    ev: DiagEvent,
    vehicle: Vehicle,
    nuisance: Nuisance,
    effects: Sequence[EffectSetting] = (),
    model: str = "multibody",
) -> Prediction:
    """Predicted measured speed of one event; ``vehicle`` already carries the vehicle effects.

    Parameters
    ----------
    ev : the event.
    vehicle : base vehicle with :func:`vehicle_with` applied.
    nuisance : nuisance parameters (the road load is already in ``vehicle``).
    effects : all effect settings (input and output transforms are applied here).
    model : simulator model name.
    """
    tq = torque_input(ev, nuisance, effects)
    res = simulate(vehicle, ev.t_fine, tq, model=model, speed0_rpm=ev.speed0(), interp="linear",
                   output_dt=FINE_DT)
    t_out = np.asarray(res.t, dtype=np.float64)
    sp = np.asarray(res.motor_speed_rpm, dtype=np.float64)
    for eff, vals in effects:
        if eff.output_transform is not None:
            sp = eff.output_transform(t_out, sp, vals)
    at = np.interp(ev.speed_t, t_out, sp)
    w = 1.0 / ev.var[ev.pre]
    anchor = float(np.sum(w * (ev.speed_meas[ev.pre] - at[ev.pre])) / np.sum(w)) if ev.pre.any() else 0.0
    return Prediction(at + anchor, t_out, sp, _gap_any(res, t_out.size), anchor)


def weighted_residual(ev: DiagEvent, pred: Prediction) -> FloatArray:
    """(n,) residual in noise units: ``(measured - predicted) / sqrt(var)``."""
    return np.asarray((ev.speed_meas - pred.speed) / np.sqrt(ev.var), dtype=np.float64)
