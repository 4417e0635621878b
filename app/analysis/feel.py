"""The felt side of one event: drivability criteria of the measured and the simulated acceleration.

The measured acceleration is the log's :class:`~app.analysis.accel.AccelSource` (an accelerometer,
else derived from the road speed). The simulated one is taken the same way, so both sides see the
same sampling and filters: with an accelerometer, the simulator's body acceleration
(:attr:`sim.SimResult.vehicle_accel_ms2`) at the accelerometer's time stamps; with a derived one,
the simulated road speed at the road-speed samples through the same differentiator. The
simulation is shifted by the analysis' torque-to-speed offset like the simulated speed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from app.analysis.accel import AccelSource, derive
from app.analysis.drivability import (
    CRITERIA_NAMES,
    Drivability,
    DrivabilityParams,
    difference,
    drivability_criteria,
    pedal_move,
)
from app.analysis.series import FloatArray
from app.analysis.zerophase import butter_sos, zero_phase
from app.serial import Serial, rule
from app.signals import Signal

PAD_S = 0.3  # filter run-in on each side of the event window


@dataclass(frozen=True)
class FeelComparison(Serial):
    source: str  # accelerometer | vehicle_speed | wheel_speed
    measured: Drivability
    simulated: Drivability  # the simulated side compared (difference): the body's, or the seat rail's on request
    difference: dict[str, float]
    simulated_at: str = "body"  # body | seat_rail: where ``simulated`` was taken
    # the seat rail's criteria where the simulation has them
    simulated_seat: Drivability | None = field(default=None, metadata=rule(omit_none=True))


def event_feel(src: AccelSource, sim_t: FloatArray, sim_speed_ms: FloatArray, sim_accel_ms2: FloatArray,
               t_start: float, t_end: float, t_cross: float, direction: float, params: DrivabilityParams, *,
               pedal: Signal | None = None, t_close_measured: float = math.nan,
               t_close_simulated: float = math.nan, shuffle_hint_hz: float = math.nan,
               sim_seat_ms2: FloatArray | None = None) -> FeelComparison:
    """Criteria of the measured and simulated acceleration of one event window (times already offset-corrected).

    ``sim_t`` (s), ``sim_speed_ms`` (m/s), ``sim_accel_ms2`` (m/s^2), shape (n,) each: the simulation of the window;
    ``sim_seat_ms2`` (n,) its seat-rail acceleration (:attr:`sim.SimResult.seat_rail_accel_ms2`) or None. The
    seat rail is read like an accelerometer at the measured side's sample times (band-limited to their rate);
    it is the compared side when ``params.compare_with`` is ``"seat_rail"``, otherwise reported beside.
    """
    moved = pedal_move(pedal, t_start, t_cross, params)  # the same driver input for both sides
    # src.t is a uniform grid: the window is a slice
    i0, i1 = int(np.searchsorted(src.t, t_start - PAD_S)), int(np.searchsorted(src.t, t_end + PAD_S, side="right"))
    t = src.t[i0:i1]
    measured = drivability_criteria(t, src.a[i0:i1], t_start, t_end, t_cross, direction, params, pedal_time=moved,
                                    t_close=t_close_measured, bandwidth_hz=src.bandwidth_hz,
                                    shuffle_hint_hz=shuffle_hint_hz, saturated=src.saturated_in(t_start, t_end),
                                    noise_ms2=src.noise_ms2)
    ts = t[int(np.searchsorted(t, sim_t[0], side="left")):int(np.searchsorted(t, sim_t[-1], side="right"))]
    if src.kind == "accelerometer":
        a_sim = np.interp(ts, sim_t, _band_limit(sim_t, sim_accel_ms2, src.period_s))
    elif ts.size > 8:
        a_sim, _ = derive(ts, np.interp(ts, sim_t, sim_speed_ms), params.derive_cutoff_hz)
    else:
        a_sim = np.interp(ts, sim_t, sim_accel_ms2)
    simulated = drivability_criteria(ts, a_sim, t_start, t_end, t_cross, direction, params, pedal_time=moved,
                                     t_close=t_close_simulated, bandwidth_hz=src.bandwidth_hz,
                                     shuffle_hint_hz=shuffle_hint_hz)
    seat = None
    if sim_seat_ms2 is not None and ts.size:
        seat = drivability_criteria(ts, np.interp(ts, sim_t, _band_limit(sim_t, sim_seat_ms2, src.period_s)), t_start,
                                    t_end, t_cross, direction, params, pedal_time=moved, t_close=t_close_simulated,
                                    shuffle_hint_hz=shuffle_hint_hz)
    if params.compare_with == "seat_rail" and seat is not None:
        return FeelComparison(src.kind, measured, seat, difference(measured, seat), "seat_rail", seat)
    return FeelComparison(src.kind, measured, simulated, difference(measured, simulated), "body", seat)


def run_feel(t: FloatArray, accel_ms2: FloatArray, torque_nm: FloatArray,
             params: DrivabilityParams | None = None) -> Drivability:
    """The criteria of a simulated run without events (a scripted tip-in, a what-if): around the first
    torque zero crossing with a step of at least 10 N m (else the steepest torque change), over the
    window an analysis would use (0.5 s before, 1.5 s after, within the run). ``t`` (s), ``accel_ms2``,
    ``torque_nm`` (n,) on one grid; no pedal, so no response delay."""
    p = params or DrivabilityParams()
    sign = np.sign(torque_nm)
    cross = np.nonzero((sign[:-1] < 0) != (sign[1:] < 0))[0]
    last = torque_nm.size - 1
    k = next((i for i in (int(c) for c in cross)
              if abs(float(torque_nm[min(i + 50, last)]) - float(torque_nm[max(i - 50, 0)])) >= 10.0), None)
    if k is None:
        k = int(np.argmax(np.abs(np.gradient(torque_nm))))
    t_cross = float(t[k])
    after = float(np.median(torque_nm[k:min(k + 200, torque_nm.size)]))
    before = float(np.median(torque_nm[max(k - 200, 0):k + 1]))
    direction = 1.0 if after >= before else -1.0
    return drivability_criteria(t, accel_ms2, max(float(t[0]), t_cross - 0.5), min(float(t[-1]), t_cross + 1.5),
                                t_cross, direction, p, pedal_time=(math.nan, "a simulated run has no pedal"))


def _band_limit(t: FloatArray, a: FloatArray, period_s: float) -> FloatArray:
    """``a`` low-passed (zero phase) to 0.45 of the rate it is about to be sampled at, as a sensor's
    anti-alias filter does; unchanged when it is not finer than that."""
    dt = float((t[-1] - t[0]) / (t.size - 1)) if t.size > 1 else math.inf
    if not (math.isfinite(period_s) and dt < 0.5 * period_s and t.size > 16):
        return a
    fs = float(f"{1.0 / dt:.6g}")
    return zero_phase(butter_sos(4, float(f"{0.45 / period_s:.4g}"), "low", fs), a)


#: criteria signed in the vehicle's frame (forward positive) rather than along the torque change: a tip-in
#: settles forward, a tip-out backward, so a median over both kinds of event describes neither
SIGNED_CRITERIA: tuple[str, ...] = ("settled_accel_ms2",)
EVENT_KINDS: tuple[str, ...] = ("tip_in", "tip_out")


def summarize_feel(rows: list[FeelComparison], kinds: list[str] | None = None) -> dict[str, dict[str, object]]:
    """Per criterion: median measured, simulated and difference over events, and how many events count; with
    ``kinds`` (each row's event kind, ``tip_in`` or ``tip_out``) the same per kind under ``tip_in`` and
    ``tip_out``. Drivability is judged per manoeuvre: the per-kind medians are the ones to read, and for a
    criterion in :data:`SIGNED_CRITERIA` the medians over all events are NaN (null), only its count is kept."""
    out: dict[str, dict[str, object]] = {}
    kind_of = np.array(kinds if kinds is not None else [""] * len(rows), dtype=object)
    if kind_of.size != len(rows):
        raise ValueError(f"{kind_of.size} event kinds for {len(rows)} rows")
    for k in CRITERIA_NAMES:
        meas = np.array([getattr(r.measured, k) for r in rows], float)
        sim = np.array([getattr(r.simulated, k) for r in rows], float)
        row: dict[str, object] = dict(_medians(meas, sim))
        if k in SIGNED_CRITERIA:
            row.update(measured_median=math.nan, simulated_median=math.nan, difference_median=math.nan)
        if kinds is not None:
            for kind in EVENT_KINDS:
                sel = kind_of == kind
                row[kind] = _medians(meas[sel], sim[sel])
        out[k] = row
    return out


def _medians(meas: FloatArray, sim: FloatArray) -> dict[str, float]:
    return {"measured_median": _med(meas), "simulated_median": _med(sim), "difference_median": _med(sim - meas),
            "events": int(np.isfinite(meas).sum())}


def _med(x: FloatArray) -> float:
    return float(np.nanmedian(x)) if np.isfinite(x).any() else float("nan")
