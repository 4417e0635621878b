"""Gap-open time against the simulator's truth, through the analysis pipeline, at 1 kHz and 100 Hz.

A scripted tip-in/tip-out drive (``app.demo.scenario``) is simulated with a "true" vehicle;
its motor speed and torque are sampled like a CAN log (period, speed delay, noise, jitter) and
analysed against the nominal vehicle with :func:`app.pipeline.analyze_signals` (event
detection, torque-to-speed offset, metrics). Truth per event: ``sim.metrics.unloaded_time`` of
the true run, first gap opening to every gap closed again.

``python -m tests.analysis.gap_validation`` prints the table quoted in docs/metrics.md.
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np

from app.analysis.events import PEDAL, SPEED, TORQUE, VEHICLE_SPEED
from app.analysis.series import FloatArray
from app.demo.scenario import Scenario, torque_script
from app.pipeline import AnalysisOptions, analyze_signals
from app.signals import Signal, SignalSet
from sim import Vehicle, load_vehicle, simulate
from sim.metrics import unloaded_time


@dataclass(frozen=True)
class Sampling:
    period_s: float
    speed_lag_s: float = 0.008
    speed_noise_rpm: float = 1.5
    torque_noise_nm: float = 0.4
    jitter_s: float = 0.0003


@dataclass(frozen=True)
class Row:
    """One analysed event: truth and both estimates (s)."""

    direction: float
    truth_s: float
    gap_open_s: float
    rising_edge_s: float


def _sampled(rng: np.random.Generator, name: str, unit: str, t: FloatArray, y: FloatArray, s: Sampling,
             lag: float, noise: float) -> Signal:
    ts = np.arange(0.003, float(t[-1]) - lag - s.period_s, s.period_s)
    ts = ts + rng.uniform(-s.jitter_s, s.jitter_s, ts.size) * (s.period_s > 0.002)
    vals = np.interp(ts - lag, t, y) + rng.normal(0.0, noise, ts.size)
    return Signal(name, ts, vals, unit)


def drive(truth_changes: dict[str, float], sampling: Sampling, duration_s: float = 40.0,
          seed: int = 7) -> tuple[Vehicle, SignalSet, list[tuple[str, float, float]]]:
    """The nominal vehicle, the sampled channels and the true run's gap events."""
    nominal = load_vehicle("paper")
    truth = nominal.with_changes(truth_changes)
    sc = Scenario(duration_s=duration_s, seed=seed, brake_cycle=-1)
    t, torque, pedal, _ = torque_script(nominal, sc)
    res = simulate(truth, t, torque, model="multibody", interp="linear", output_dt=0.001)
    rng = np.random.default_rng(seed + 1)
    sigs = SignalSet()
    sigs.add(_sampled(rng, TORQUE, "N m", t, torque, sampling, 0.0, sampling.torque_noise_nm))
    sigs.add(_sampled(rng, SPEED, "rpm", res.t, res.motor_speed_rpm, sampling, sampling.speed_lag_s,
                      sampling.speed_noise_rpm))
    sigs.add(_sampled(rng, PEDAL, "%", t, pedal, sampling, 0.0, 0.0))
    sigs.add(_sampled(rng, VEHICLE_SPEED, "km/h", res.t, res.vehicle_speed_kmh, sampling, 0.0, 0.02))
    return nominal, sigs, list(res.gap_events)


def validate(truth_changes: dict[str, float], sampling: Sampling, duration_s: float = 40.0,
             seed: int = 7) -> list[Row]:
    nominal, sigs, gap_events = drive(truth_changes, sampling, duration_s, seed)
    result = analyze_signals(sigs, nominal, AnalysisOptions(whole_log=False))
    rows = []
    for er in result.event_results:
        if er.comparison is None:
            continue
        tc = er.event.t_cross_s
        truth = unloaded_time(gap_events, tc - 0.2, tc + 0.3)
        m = er.comparison.measured
        rows.append(Row(er.event.direction, truth, m.gap_open_time_s, m.rising_edge_time_s))
    return rows


def errors_ms(rows: list[Row], field: str) -> FloatArray:
    return np.array([(getattr(r, field) - r.truth_s) * 1e3 for r in rows])


CASES: tuple[tuple[str, dict[str, float]], ...] = (
    ("half-shaft gap x0.5", {"gaps.halfshaft": 0.012}),
    ("half-shaft gap x0.8", {"gaps.halfshaft": 0.0192}),
    ("nominal", {}),
    ("half-shaft gap x1.5", {"gaps.halfshaft": 0.036}),
    ("rotor inertia +15 %", {"motor.rotor_inertia": 0.046}),
)


def main() -> int:
    print("gap-open time vs the simulator's unloaded time (first gap open -> all closed), per event, ms")
    print(f"{'truth vehicle':<22} {'sampling':<8} {'n':>3} {'truth':>6} {'estimate':>8} {'bias':>6} {'sd':>5} "
          f"{'p90 |err|':>9} {'found':>6} {'rising edge':>11} {'its bias':>8}")
    for label, changes in CASES:
        for period, name in ((0.001, "1 kHz"), (0.01, "100 Hz")):
            rows = validate(changes, Sampling(period))
            err = errors_ms(rows, "gap_open_s")
            ok = np.isfinite(err)
            edge = errors_ms(rows, "rising_edge_s")
            print(f"{label:<22} {name:<8} {len(rows):>3} {np.mean([r.truth_s for r in rows]) * 1e3:>6.1f} "
                  f"{np.nanmean([r.gap_open_s for r in rows]) * 1e3:>8.1f} {np.mean(err[ok]):>+6.1f} "
                  f"{np.std(err[ok]):>5.1f} {np.percentile(np.abs(err[ok]), 90):>9.1f} {ok.sum():>3}/{ok.size:<2} "
                  f"{np.nanmean([r.rising_edge_s for r in rows]) * 1e3:>11.1f} {np.nanmean(edge):>+8.1f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
