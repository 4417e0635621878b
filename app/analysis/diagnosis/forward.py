"""Event data and the forward model: measured torque of one event -> predicted measured speed.

Only the event windows are simulated. For one event and one parameter set the prediction is::

    torque_in(t)  = gain * T_can(t) + input effects                   (1 ms grid, monotone cubic)
    speed_sim     = simulate(vehicle + vehicle effects, torque_in, speed0 = measured speed at sim_t0)
    speed_pred(t) = output effects(speed_sim)(t - offset) + c_e       at the measured sample times

The simulation starts at ``sim_t0``, the last *quasi-static* point before the scored window
(see :func:`.prepare.warm_start`): where the torque had been steady long enough for the shuffle
of any earlier reversal to have decayed, or the log start. The simulator's own initial state is
quasi-static, so this is the only start that is not fictitious; a reversal less than a few
seconds after the previous one is simulated through that one (the warm-up), and its window starts
from the state the continuous run carries into it. Only the samples of the window are scored.

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

import os
from collections.abc import Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.interpolate import PchipInterpolator

from app.analysis.diagnosis.offset_kernel import shifted_residuals
from app.serial import Serial, rule
from sim import SimResult, Vehicle, simulate
from sim.effects.base import Effect
from sim.simulate import SpeedRun, simulate_speed

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

FINE_DT = 0.001  # s: grid of the simulated torque input and output
# clusters simulated side by side (the integrator runs without the interpreter lock); at most the usable cores
SIM_THREADS = max(1, min(4, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1))
_POOL: tuple[int, ThreadPoolExecutor] | None = None


def sim_pool() -> ThreadPoolExecutor:
    """This process's pool of simulation threads (a forked child never reuses its parent's, whose threads it
    does not have)."""
    global _POOL
    if _POOL is None or _POOL[0] != os.getpid():
        _POOL = (os.getpid(), ThreadPoolExecutor(max_workers=SIM_THREADS, thread_name_prefix="lashscope-sim"))
    return _POOL[1]
# the cheaper per-pass paths with the same numbers: multibody runs through sim.simulate.simulate_speed (resolver
# speed and gap states only) and the offset profile's residuals compiled (shifted_chi2_compiled); False: the full
# SimResult and the numpy profile (the benchmark's and the tests' reference)
LEAN_SIM = True
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
    sim_t0 : start of the simulation (s), at or before ``t_start - MARGIN_S``; None: ``t_start - MARGIN_S``.
    speed_init_rpm : measured speed at ``sim_t0`` (rpm); None: from the window's first samples.
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
    sim_t0: float | None = None
    speed_init_rpm: float | None = None
    t_fine: FloatArray = field(init=False, repr=False)
    torque_fn: PchipInterpolator = field(init=False, repr=False)
    # the torque filled in on a run's fine grid before gain and input effects, per cluster this event starts
    # (see simulate_events): the same for every parameter set a fit tries
    _raw: dict[tuple[object, ...], tuple[tuple[DiagEvent, ...], FloatArray, FloatArray]] = field(
        init=False, repr=False, compare=False, default_factory=dict)

    def __post_init__(self) -> None:
        t0 = self.t_start - MARGIN_S if self.sim_t0 is None else min(self.sim_t0, self.t_start - MARGIN_S)
        t0 = max(t0, float(self.torque_t[0]))
        n = round((self.t_end + MARGIN_S - t0) / FINE_DT) + 1
        object.__setattr__(self, "t_fine", t0 + FINE_DT * np.arange(n, dtype=np.float64))
        # monotone cubic: follows a smooth torque request through its samples without overshoot, where
        # straight lines would cut the corners of every ramp by up to half a CAN period
        object.__setattr__(self, "torque_fn", PchipInterpolator(self.torque_t, self.torque_nm, extrapolate=False))

    @property
    def n(self) -> int:
        return int(self.speed_t.size)

    @property
    def warm_s(self) -> float:
        """Simulated time before the scored window (s): the warm-up through earlier reversals."""
        return max(float(self.speed_t[0] - self.t_fine[0]), 0.0)

    def speed0(self) -> float:
        """Measured speed at the simulation start: a line through the first 50 ms of samples."""
        if self.speed_init_rpm is not None:
            return float(self.speed_init_rpm)
        m = self.speed_t <= self.speed_t[0] + 0.05
        if int(m.sum()) < 3:
            return float(self.speed_meas[0])
        c = np.polyfit(self.speed_t[m] - self.speed_t[0], self.speed_meas[m], 1)
        return float(np.polyval(c, self.t_fine[0] - self.speed_t[0]))


@dataclass(frozen=True)
class Nuisance(Serial):
    """Nuisance parameters: torque-speed time offset (s), torque gain (-), road load (grade %)."""

    offset_s: float = 0.0
    gain: float = 1.0
    grade_pct: float = field(default=0.0, metadata=rule(key="road_load_grade_pct"))


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
    return base.with_changes(changes)


def _cluster_torque(events: Sequence[DiagEvent]) -> tuple[FloatArray, FloatArray]:
    """The CAN torque samples of several events, merged (the same log sample appears once)."""
    t = np.concatenate([ev.torque_t for ev in events])
    v = np.concatenate([ev.torque_nm for ev in events])
    t_u, first = np.unique(t, return_index=True)
    return np.asarray(t_u, dtype=np.float64), np.asarray(v[first], dtype=np.float64)


def _filled(t_fine: FloatArray, torque_t: FloatArray, torque_nm: FloatArray, interp: str,
            fn: PchipInterpolator | None = None) -> FloatArray:
    """CAN torque filled in on ``t_fine`` (N m), held beyond its first and last sample."""
    tq_t = np.clip(t_fine, torque_t[0], torque_t[-1])
    if interp == "pchip":
        raw = (fn if fn is not None else PchipInterpolator(torque_t, torque_nm, extrapolate=False))(tq_t)
    else:
        raw = np.interp(tq_t, torque_t, torque_nm)
    return np.asarray(raw, dtype=np.float64)


def _gained(t_fine: FloatArray, raw: FloatArray, gain: float, effects: Sequence[EffectSetting]) -> FloatArray:
    tq = gain * raw
    for eff, vals in effects:
        if eff.input_transform is not None:
            tq = eff.input_transform(t_fine, tq, vals)
    return np.asarray(tq, dtype=np.float64)


def torque_on(t_fine: FloatArray, torque_t: FloatArray, torque_nm: FloatArray, gain: float,
              effects: Sequence[EffectSetting], interp: str = "pchip",
              fn: PchipInterpolator | None = None) -> FloatArray:
    """Torque on ``t_fine`` after gain and input effects (N m); ``interp``: "pchip" or "linear"."""
    return _gained(t_fine, _filled(t_fine, torque_t, torque_nm, interp, fn), gain, effects)


def _run_torque(events: Sequence[DiagEvent], group: Sequence[int], interp: str) -> tuple[FloatArray, FloatArray]:
    """Fine grid and filled-in torque (before gain) of one cluster's continuous run, cached on its first
    event: a fit simulates the same events for dozens of parameter sets."""
    members = tuple(events[i] for i in group)
    first = members[0]
    key = (interp, *(float(ev.t_fine[0]) for ev in members))
    hit = first._raw.get(key)
    if hit is not None and len(hit[0]) == len(members) and all(a is b for a, b in zip(hit[0], members, strict=True)):
        return hit[1], hit[2]
    if len(members) == 1:
        grid, raw = first.t_fine, _filled(first.t_fine, first.torque_t, first.torque_nm, interp, first.torque_fn)
    else:
        t_end = max(float(ev.t_fine[-1]) for ev in members)
        grid = first.t_fine[0] + FINE_DT * np.arange(round((t_end - first.t_fine[0]) / FINE_DT) + 1)
        tq_t, tq_v = _cluster_torque(members)
        raw = _filled(grid, tq_t, tq_v, interp)
    first._raw[key] = (members, grid, raw)
    return grid, raw
def torque_input(ev: DiagEvent, gain: float, effects: Sequence[EffectSetting], interp: str = "pchip") -> FloatArray:
    """Torque on the event's fine grid after gain and input effects (N m); ``interp``: "pchip" or "linear"."""
    return torque_on(ev.t_fine, ev.torque_t, ev.torque_nm, gain, effects, interp, ev.torque_fn)


def _gap_any(res: Any, n: int) -> BoolArray | None:
    """Any backlash open at each output sample (the simulator reports one mask per gap)."""
    g = getattr(res, "gap_open", None)
    if not g:
        return None
    masks = [np.asarray(m, dtype=bool) for m in (g.values() if isinstance(g, Mapping) else [g])]
    masks = [m for m in masks if m.shape == (n,)]
    return np.logical_or.reduce(masks) if masks else None


def clusters(events: Sequence[DiagEvent]) -> list[list[int]]:
    """Positions in ``events`` grouped into runs whose simulated spans overlap, in time order.

    Each group is simulated once, continuously from its first event's start: an event whose
    warm-up reaches back into the previous event's span gets the state that run carries, and a
    log of close reversals costs one simulation of its length per parameter set instead of one
    warm-up per event.
    """
    order = sorted(range(len(events)), key=lambda i: float(events[i].t_fine[0]))
    groups: list[list[int]] = []
    end = -np.inf
    for i in order:
        ev = events[i]
        if groups and float(ev.t_fine[0]) <= end + 0.5 * FINE_DT:
            groups[-1].append(i)
        else:
            groups.append([i])
        end = max(end, float(ev.t_fine[-1])) if len(groups[-1]) > 1 else float(ev.t_fine[-1])
    return groups


def simulate_events(events: Sequence[DiagEvent], vehicle: Vehicle, gain: float,
                    effects: Sequence[EffectSetting] = (), model: str = "multibody",
                    interp: str = "pchip", gaps: bool = True, threads: bool = True) -> list[SimOut]:
    """Simulator output of every event, one continuous run per cluster (:func:`clusters`).

    ``gaps=False``: no gap states (``SimOut.gap_open`` None), for a caller that reads the speed only (a fit's
    residuals); the speed is the same. ``threads=False``: the clusters one after the other in this thread (for a
    caller that is itself on the simulation pool).

    ``vehicle`` already carries the vehicle effects; input effects act on the run's torque and
    output effects on its speed, so their own states carry through the cluster too. Each event
    gets the run's output over its own fine-grid span.
    """
    outs: list[SimOut | None] = [None] * len(events)
    groups = clusters(events)

    def run(group: list[int]) -> SimResult | SpeedRun:
        grid, raw = _run_torque(events, group, interp)
        tq = _gained(grid, raw, gain, effects)
        if model == "multibody" and LEAN_SIM:  # the same run, without the outputs no caller here reads
            return simulate_speed(vehicle, grid, tq, speed0_rpm=events[group[0]].speed0(), interp="linear",
                                  output_dt=FINE_DT, gaps=gaps)
        return simulate(vehicle, grid, tq, model=model, speed0_rpm=events[group[0]].speed0(), interp="linear",
                        output_dt=FINE_DT)

    # the integrator releases the interpreter lock: clusters run side by side on the machine's cores
    runs = (list(sim_pool().map(run, groups)) if threads and SIM_THREADS > 1 and len(groups) > 1
            else [run(g) for g in groups])
    for group, res in zip(groups, runs, strict=True):
        t_out = np.asarray(res.t, dtype=np.float64)
        sp = np.asarray(res.motor_speed_rpm, dtype=np.float64)
        for eff, vals in effects:
            if eff.output_transform is not None:
                sp = eff.output_transform(t_out, sp, vals)
        gap = _gap_any(res, t_out.size)
        for i in group:
            ev = events[i]
            m = (t_out >= ev.t_fine[0] - 0.5 * FINE_DT) & (t_out <= ev.t_fine[-1] + 0.5 * FINE_DT)
            outs[i] = SimOut(t_out[m], sp[m], None if gap is None else gap[m])
    return [o for o in outs if o is not None]


def simulate_event(ev: DiagEvent, vehicle: Vehicle, gain: float, effects: Sequence[EffectSetting] = (),
                   model: str = "multibody", interp: str = "pchip") -> SimOut:
    """One simulator run over the event's fine grid; ``vehicle`` already carries the vehicle effects."""
    return simulate_events([ev], vehicle, gain, effects, model, interp)[0]


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


def shifted_chi2_compiled(events: Sequence[DiagEvent], outs: Sequence[SimOut], offsets: FloatArray) -> FloatArray:
    """:func:`shifted_chi2` with each event's residuals from a compiled call (:mod:`.offset_kernel`): the same
    residuals and the same numpy sums, so the same totals bit for bit; one buffer, reused while it is in cache,
    instead of numpy's temporaries."""
    if any(out.t.size == 0 for out in outs):  # numpy's own error
        return shifted_chi2(events, outs, offsets)
    k = offsets.size
    grid = np.ascontiguousarray(offsets, dtype=np.float64)
    buf = np.empty(k * max((ev.n for ev in events), default=0))
    total = np.zeros(k)
    for ev, out in zip(events, outs, strict=True):
        r = buf[:k * ev.n].reshape(k, ev.n)
        shifted_residuals(ev.speed_t, ev.speed_meas, out.t, out.speed, grid, r)
        w = 1.0 / ev.var  # from here on shifted_chi2's own operations
        if ev.pre.any():
            wp = w[ev.pre]
            r = r - (r[:, ev.pre] @ wp / wp.sum())[:, None]
        total += (r * r) @ w
    return total


def best_offset(events: Sequence[DiagEvent], outs: Sequence[SimOut], bounds: tuple[float, float],
                step: float = 0.0005) -> float:
    """Offset (s) within ``bounds`` minimising the total weighted SSE: grid, then a parabola (the grid scored by
    :func:`shifted_chi2_compiled`, or by the numpy :func:`shifted_chi2` when :data:`LEAN_SIM` is off)."""
    grid = np.arange(bounds[0], bounds[1] + step / 2, step)
    chi = shifted_chi2_compiled(events, outs, grid) if LEAN_SIM else shifted_chi2(events, outs, grid)
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
