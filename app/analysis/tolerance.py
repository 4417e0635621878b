"""Predicted ripple band over the vehicle's tolerance bands, and where each measured ripple falls in it.

For every analysed event the measured motor torque over the event window drives a Monte Carlo
of the driveline (:func:`sim.batch.tolerance_analysis`: every gap sampled in its [min, max]
band and every ``vehicle.tolerances`` band, uniformly), from the measured speed at the window
start. The ripple compared is the same on both sides: the paper's peak-to-adjacent-valley
fluctuation of the motor speed (:func:`sim.metrics.peak_to_valley`) over the event window, for
each variant and for the measured speed. The measured percentile is the share of variants whose
fluctuation is at most the measured one (0-100).

What the occupants feel is predicted the same way when the window knows its torque crossing: every
variant's body acceleration (the derivative of its vehicle speed) gives the shuffle peak-to-peak of
:mod:`app.analysis.drivability`; ``band_shuffle_pp_ms2`` is its band, ``nominal_shuffle_pp_ms2`` the
nominal vehicle's.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
import numpy.typing as npt

from app.analysis.drivability import drivability_criteria
from app.errors import InputError
from app.progress import Progress, no_progress
from app.signals import Signal
from sim import SimError, Vehicle
from sim.batch import ToleranceResult, ToleranceSample, tolerance_analysis, tolerance_sample
from sim.metrics import peak_to_valley

MAX_SAMPLES = 2000  # variants per event: the cost is linear in this
BAND_PERCENTILES = (5.0, 50.0, 95.0)


@dataclass(frozen=True)
class EventWindow:
    """One event to predict: its index and kind, the simulated span and the metric window (s)."""

    index: int
    kind: str
    t_sim_start_s: float
    t_start_s: float
    t_end_s: float
    t_cross_s: float = float("nan")  # torque zero crossing: the felt criteria need it (NaN: not computed)


def check_request(n: int, seed: int) -> None:
    """Raise InputError unless ``n`` variants (1..MAX_SAMPLES) and ``seed`` (>= 0) are usable."""
    if not 1 <= n <= MAX_SAMPLES:
        raise InputError(f"tolerance: n = {n} variants; use 1..{MAX_SAMPLES}")
    if seed < 0:
        raise InputError(f"tolerance: seed = {seed}; use a non-negative integer")


def band_of(res: ToleranceResult) -> dict[str, float]:
    """The predicted fluctuation (rpm) at :data:`BAND_PERCENTILES`, keyed ``p5``, ``p50``, ``p95``."""
    vals = np.percentile(res.fluct_rpm, BAND_PERCENTILES)
    return {f"p{p:g}": float(v) for p, v in zip(BAND_PERCENTILES, vals, strict=True)}


def event_tolerance(vehicle: Vehicle, torque: Signal, speed: Signal, window: EventWindow, n: int, seed: int,
                    interp: Literal["hold", "linear"] = "linear",
                    progress: Callable[[int, int], None] | None = None, sample: ToleranceSample | None = None,
                    ) -> tuple[dict[str, Any], ToleranceResult | None]:
    """Band and measured percentile for one event; the dict says ``error`` when the event cannot be run.

    Returns the JSON-ready row and the raw :class:`ToleranceResult` (None on error);
    ``progress(done, n)`` follows the variants. ``sample``: the variants drawn once for all events
    (:func:`sim.batch.tolerance_sample` of ``vehicle``, ``n``, ``seed``), so each is built once.
    """
    row: dict[str, Any] = {"index": window.index, "kind": window.kind, "t_start_s": window.t_start_s,
                           "t_end_s": window.t_end_s}
    m = (torque.t >= window.t_sim_start_s) & (torque.t <= window.t_end_s)
    tq_t, tq_v = torque.t[m], torque.values[m]
    if tq_t.size < 2:
        return {**row, "error": f"torque has {tq_t.size} samples in the event window"}, None
    w = speed.window(window.t_start_s, window.t_end_s)
    if len(w) < 2:
        return {**row, "error": f"measured speed has {len(w)} samples in the event window"}, None
    speed0 = float(speed.at([tq_t[0]])[0])
    felt = bool(np.isfinite(window.t_cross_s))
    try:
        res = tolerance_analysis(vehicle, tq_t, tq_v, n=n, seed=seed, window=(window.t_start_s, window.t_end_s),
                                 speed0_rpm=speed0 if np.isfinite(speed0) else None, interp=interp,
                                 progress=progress, body_speed=felt, sample=sample)
    except SimError as exc:
        return {**row, "error": f"simulation failed: {exc}"}, None
    measured = peak_to_valley(w.t, w.values, window.t_start_s, window.t_end_s)
    row.update(nominal_fluctuation_rpm=res.nominal_fluct_rpm, band_rpm=band_of(res),
               measured_fluctuation_rpm=measured, measured_percentile=res.percentile_of(measured),
               unloaded_ms_median=float(np.median(res.unloaded_ms)), error=None)
    if felt and res.t is not None and res.vehicle_speed_kmh is not None:
        pp = felt_shuffle(res.t, res.vehicle_speed_kmh, window)
        finite = pp[1:][np.isfinite(pp[1:])]
        row["nominal_shuffle_pp_ms2"] = float(pp[0])
        row["band_shuffle_pp_ms2"] = ({f"p{q:g}": float(v) for q, v in
                                       zip(BAND_PERCENTILES, np.percentile(finite, BAND_PERCENTILES), strict=True)}
                                      if finite.size else None)
    return row, res


def felt_shuffle(t: npt.NDArray[np.float64], vehicle_speed_kmh: npt.NDArray[np.float64],
                 window: EventWindow) -> npt.NDArray[np.float64]:
    """Shuffle peak-to-peak (m/s^2) of every run's body acceleration over the event window, (runs,)."""
    direction = 1.0 if window.kind == "tip_in" else -1.0
    out = np.full(vehicle_speed_kmh.shape[0], np.nan)
    for k, v in enumerate(vehicle_speed_kmh):
        accel = np.gradient(v / 3.6, t)
        out[k] = drivability_criteria(t, accel, window.t_start_s, window.t_end_s, window.t_cross_s, direction,
                                      pedal_time=(np.nan, "not needed")).shuffle_pp_ms2
    return out


def tolerance_doc(vehicle: Vehicle, torque: Signal, speed: Signal, windows: Sequence[EventWindow], n: int, seed: int,
                  progress: Progress = no_progress) -> dict[str, Any]:
    """:func:`event_tolerance` for every window, with the sampled fields; progress 0..1 (stage ``tolerance``)
    per event done, from the simulator's count of variants."""
    check_request(n, seed)
    sample = tolerance_sample(vehicle, n, seed)  # every event runs the same variants, each built once
    rows: list[dict[str, Any]] = []
    fields: tuple[str, ...] = ()
    for k, win in enumerate(windows):
        def step(done: int, total: int, k: int = k) -> None:
            progress((k + done / max(1, total)) / max(1, len(windows)), "tolerance")

        row, res = event_tolerance(vehicle, torque, speed, win, n, seed, progress=step, sample=sample)
        if res is not None:
            fields = res.fields
        rows.append(row)
        progress((k + 1) / max(1, len(windows)), "tolerance")
    return {"n": n, "seed": seed, "distribution": "uniform", "percentiles": list(BAND_PERCENTILES),
            "metric": "peak-to-adjacent-valley fluctuation of the raw motor speed over the event window (rpm; not "
                      "detrended, unlike the analysis' metrics)",
            "felt_metric": "shuffle peak-to-peak of the body acceleration (m/s^2, docs/drivability.md)",
            "sampled_fields": list(fields), "events": rows}
