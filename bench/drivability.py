"""Drivability benchmark: criteria against known accelerations, speed-derived acceleration, the rating fit,
and what the criteria cost an analysis.

1. **Analytic truth at 100 Hz**: second-order step responses (the shuffle after a tip-in) over a grid of
   frequencies 2.5-9 Hz and damping ratios 0.08-0.25, seen by a 100 Hz accelerometer (causal 30 Hz
   anti-alias filter, 0.12 m/s^2 offset, 0.04 m/s^2 white noise, 0.001 m/s^2 quantisation). Truth:
   kick, first-swing peak-to-peak and frequency in closed form, VDV of the noise-free signal at 10 kHz.
   Printed: median and worst relative error per criterion (target: within 5 %).
2. **Simulated truth**: the demo drive (paper preset), its body acceleration at 1 kHz without noise as
   truth, against the criteria the analysis computes from the 100 Hz accelerometer of the same drive.
3. **Derived from speed at 50 Hz**: the same drive with only 50 Hz wheel speeds (no accelerometer, no
   vehicle speed); per event the derived shuffle peak-to-peak against the accelerometer's, or flagged
   unresolved (target: within 15 % or flagged).
4. **Rating fit**: 60 events with criteria drawn over realistic ranges, scored by a known monotone rule
   plus noise (sigma 0.3 points, rounded to half points as people score); cross-validated RMS error of
   the fit against the scores and RMS error against the noise-free rule on 500 new events (target: CV
   RMS <= 0.5 points).
5. **Cost**: ``run_analysis`` of the 90 s demo log with the criteria on and off, alternating, best of
   ``--repeat``; the ratio of the added time (target: <= 10 %), in wall-clock time, as the pipeline's own
   timer of the criteria, and in the process' CPU time (less disturbed by other work on a shared machine).

    .venv/bin/python bench/drivability.py
    .venv/bin/python bench/drivability.py --repeat 5
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from scipy import signal as sps

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.analysis.drivability import DrivabilityParams, drivability_criteria  # noqa: E402
from app.analysis.iso2631 import vdv  # noqa: E402
from app.analysis.ratings import FEATURES, fit_ratings  # noqa: E402
from app.demo.scenario import Scenario, measured_channels, torque_script  # noqa: E402
from app.pipeline import AnalysisOptions, VehicleInputs, analyze_signals, run_analysis  # noqa: E402
from app.signals import Interp, Signal, SignalSet  # noqa: E402
from sim import load_vehicle, simulate  # noqa: E402

PRE, SET = -0.3, 1.5
VERBOSE = False


def step_response(t: np.ndarray, f_hz: float, zeta: float) -> np.ndarray:
    wd = 2 * math.pi * f_hz
    sig = zeta * wd / math.sqrt(1 - zeta**2)
    tau = np.maximum(t, 0.0)
    resp = 1 - np.exp(-sig * tau) * (np.cos(wd * tau) + sig / wd * np.sin(wd * tau))
    return np.where(t > 0, PRE + (SET - PRE) * resp, PRE)


def accelerometer(t_fine: np.ndarray, a_fine: np.ndarray, rng: np.random.Generator, period: float = 0.01,
                  noise: float = 0.04, offset: float = 0.12) -> tuple[np.ndarray, np.ndarray]:
    fs = 1.0 / float(t_fine[1] - t_fine[0])
    sos = sps.butter(2, 30.0, fs=fs, output="sos")
    seen = sps.sosfilt(sos, a_fine, zi=sps.sosfilt_zi(sos) * a_fine[0])[0]
    ts = np.arange(t_fine[0] + rng.uniform(0, period), t_fine[-1], period)
    a = np.interp(ts, t_fine, seen) + offset + rng.normal(0.0, noise, ts.size)
    return ts, np.round(a, 3) - offset  # the analysis removes the offset it measures against the road speed


def analytic(seeds: int) -> None:
    errs: dict[str, list[float]] = {"kick": [], "p-p": [], "frequency": [], "VDV": []}
    t_fine = np.arange(-0.5, 1.5, 1e-4)
    for f in (2.5, 3.5, 5.0, 7.0, 9.0):
        for zeta in (0.08, 0.15, 0.25):
            a_fine = step_response(t_fine, f, zeta)
            wd = 2 * math.pi * f
            over = math.exp(-zeta * wd / math.sqrt(1 - zeta**2) * math.pi / wd)
            truth = {"kick": (SET - PRE) * over, "p-p": (SET - PRE) * (over + over**2), "frequency": f,
                     "VDV": vdv(a_fine, 1e4)}
            for seed in range(seeds):
                ts, a = accelerometer(t_fine, a_fine, np.random.default_rng(seed))
                d = drivability_criteria(ts, a, -0.45, 1.45, 0.0, 1.0)
                got = {"kick": d.kick_ms2, "p-p": d.shuffle_pp_ms2, "frequency": d.shuffle_freq_hz,
                       "VDV": d.vdv_ms175}
                for k in errs:
                    errs[k].append(abs(got[k] / truth[k] - 1.0) * 100)
    n = len(errs["kick"])
    print(f"1. analytic truth, 100 Hz accelerometer (noise 0.04 m/s^2, 30 Hz anti-alias), {n} events "
          "(f 2.5-9 Hz, zeta 0.08-0.25)")
    for k, v in errs.items():
        print(f"   {k:<10} median error {np.median(v):5.2f} %   95th percentile {np.percentile(v, 95):5.2f} %   "
              f"worst {np.max(v):5.2f} %")


def _signals(channels: dict[str, object], keep: set[str] | None = None, wheel_period: float | None = None) -> SignalSet:
    ss = SignalSet()
    for name, ch in channels.items():
        if keep is not None and name not in keep:
            continue
        t, v = ch.t, ch.values  # type: ignore[attr-defined]
        if wheel_period and name.startswith("wheel_speed_"):
            step = round(wheel_period / ch.period_s)  # type: ignore[attr-defined]
            t, v = t[::step], v[::step]
        ss.add(Signal.from_samples(name, t, v, interp=Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR))
    return ss


def simulated(duration: float) -> None:
    nominal = load_vehicle("paper")
    sc = Scenario(duration_s=duration)
    truth_vehicle = nominal.with_changes({k: nominal.get(k) * f for k, f in sc.truth_changes.items()})
    t, torque, _, _ = torque_script(nominal, sc)
    res = simulate(truth_vehicle, t, torque, model="multibody", interp="linear", output_dt=0.001)
    channels = measured_channels(nominal, sc)
    full = analyze_signals(_signals(channels), nominal, AnalysisOptions())
    errs: dict[str, list[float]] = {"kick": [], "p-p": [], "frequency": [], "VDV": []}
    absolute: dict[str, list[float]] = {k: [] for k in errs}
    for er in full.event_results:
        if er.feel is None:
            continue
        ev = er.event
        m = (res.t >= ev.t_start_s - 0.3) & (res.t <= ev.t_end_s + 0.3)
        true = drivability_criteria(res.t[m], res.vehicle_accel_ms2[m], ev.t_start_s, ev.t_end_s,
                                    ev.t_cross_s + (full.offset.lag_s if full.offset.applied else 0.0),
                                    ev.direction)
        got = er.feel.measured
        pairs = (("kick", got.kick_ms2, true.kick_ms2), ("p-p", got.shuffle_pp_ms2, true.shuffle_pp_ms2),
                 ("frequency", got.shuffle_freq_hz, true.shuffle_freq_hz), ("VDV", got.vdv_ms175, true.vdv_ms175))
        for k, a, b in pairs:
            if math.isfinite(a) and math.isfinite(b) and b != 0:
                errs[k].append(abs(a / b - 1.0) * 100)
                absolute[k].append(abs(a - b))
    print(f"2. simulated truth (demo drive {duration:.0f} s, body acceleration at 1 kHz) against the analysis of its "
          f"100 Hz accelerometer, {len(errs['p-p'])} events")
    units = {"kick": "m/s^2", "p-p": "m/s^2", "frequency": "Hz", "VDV": "m/s^1.75"}
    for k, v in errs.items():
        print(f"   {k:<10} median error {np.median(v):5.2f} %   worst {np.max(v):5.2f} %   "
              f"(absolute: median {np.median(absolute[k]):.3f}, worst {np.max(absolute[k]):.3f} {units[k]})")

    wheels = {f"wheel_speed_{w}_rpm" for w in ("fl", "fr", "rl", "rr")}
    keep = {"motor_torque_nm", "motor_speed_rpm", "pedal_pct", "brake_pressed", "brake", *wheels}
    by_index = {er.event.index: er.feel for er in full.event_results if er.feel is not None}
    for n, period in enumerate((0.02, 0.01)):
        derived = analyze_signals(_signals(channels, keep, wheel_period=period), nominal, AnalysisOptions())
        src = derived.acceleration
        assert src is not None
        within = flagged = outside = 0
        ratios = []
        for er in derived.event_results:
            acc = by_index.get(er.event.index)
            if er.feel is None or acc is None or not math.isfinite(acc.measured.shuffle_pp_ms2):
                continue
            pp = er.feel.measured.shuffle_pp_ms2
            if not math.isfinite(pp):
                flagged += er.feel.measured.resolution.get("shuffle_pp_ms2", "").startswith("unresolved")
                continue
            r = pp / acc.measured.shuffle_pp_ms2
            if VERBOSE:
                print(f"   event {er.event.index} {er.event.kind.value}: derived p-p {pp:.3f}, accelerometer "
                      f"{acc.measured.shuffle_pp_ms2:.3f} m/s^2")
            ratios.append(r)
            within += abs(r - 1) <= 0.15
            outside += abs(r - 1) > 0.15
        head = "3." if n == 0 else "  "
        spread = (f"; ratio median {np.median(ratios):.3f}, range {min(ratios):.3f}-{max(ratios):.3f}"
                  if ratios else "")
        print(f"{head} derived from {1 / period:.0f} Hz wheel speeds (differentiator bandwidth "
              f"{src.bandwidth_hz:.1f} Hz, noise {src.noise_ms2:.3f} m/s^2 RMS): shuffle p-p against the "
              f"accelerometer's: {within} within 15 %, {flagged} flagged unresolved, {outside} outside{spread}")


def rule(x: np.ndarray) -> np.ndarray:
    """The known scoring rule: monotone in shuffle, jerk, clunk and delay (FEATURES order)."""
    pp, kick, jerk, clunk, delay, _ = x.T
    return np.clip(9.6 - 1.5 * pp - 0.6 * kick - 0.025 * jerk - 4.0 * clunk - 6.0 * np.maximum(0, delay - 0.12),
                   1, 10)


def draw(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.column_stack((rng.uniform(0.1, 2.5, n), rng.uniform(0.05, 1.5, n), rng.uniform(8, 90, n),
                            rng.uniform(0.0, 0.4, n), rng.uniform(0.05, 0.3, n), rng.uniform(0.4, 2.0, n)))


def ratings(n: int, trials: int) -> None:
    cvs, truths = [], []
    for seed in range(trials):
        rng = np.random.default_rng(100 + seed)
        x = draw(rng, n)
        scores = np.clip(np.round((rule(x) + rng.normal(0, 0.3, n)) * 2) / 2, 1, 10)
        model = fit_ratings(x, scores, FEATURES)
        fresh = draw(rng, 500)
        cvs.append(model.cv_rms)
        truths.append(float(np.sqrt(np.mean((model.predict(fresh) - rule(fresh)) ** 2))))
    print(f"4. rating fit, {n} scored events (rule + N(0, 0.3) rounded to 0.5), {trials} draws: cross-validated RMS "
          f"{np.median(cvs):.2f} points median, {np.max(cvs):.2f} worst; against the noise-free rule on 500 new "
          f"events {np.median(truths):.2f} median, {np.max(truths):.2f} worst")


def cost(repeat: int) -> None:
    from app.demo.build import build_demo_log

    vehicle = load_vehicle("paper")
    with tempfile.TemporaryDirectory() as tmp:
        log = Path(tmp) / "demo.blf"
        build_demo_log(log, REPO / "dbc/lashscope_ev.dbc", REPO / "dbc/lashscope_ev.map.toml")
        inputs = VehicleInputs(vehicle, REPO / "dbc/lashscope_ev.dbc", REPO / "dbc/lashscope_ev.map.toml")
        on = AnalysisOptions()
        off = replace(on, drivability=DrivabilityParams(enabled=False))
        run_analysis(log, inputs, on)  # warm: numba, DBC cache
        t_on, t_off, inner, cpu_on, cpu_off = [], [], [], [], []
        for _ in range(repeat):
            c, p = time.perf_counter(), time.process_time()
            run_analysis(log, inputs, off)
            t_off.append(time.perf_counter() - c)
            cpu_off.append(time.process_time() - p)
            c, p = time.perf_counter(), time.process_time()
            res = run_analysis(log, inputs, on)
            t_on.append(time.perf_counter() - c)
            cpu_on.append(time.process_time() - p)
            inner.append(res.timings_s["drivability"])
    events = sum(1 for er in res.event_results if er.feel is not None)
    print(f"5. cost: run_analysis of the 90 s demo log ({events} events with criteria), best of {repeat}: "
          f"{min(t_off):.3f} s without the criteria, {min(t_on):.3f} s with; added "
          f"{(min(t_on) / min(t_off) - 1) * 100:.1f} % (the criteria's own timer: {min(inner) * 1e3:.0f} ms = "
          f"{min(inner) / min(t_off) * 100:.1f} %); CPU time {min(cpu_off):.3f} s without, {min(cpu_on):.3f} s "
          f"with: added {(min(cpu_on) / min(cpu_off) - 1) * 100:.1f} %")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=4, help="noise draws per analytic case")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--duration", type=float, default=60.0, help="length of the simulated drive (s)")
    ap.add_argument("--verbose", action="store_true", help="one line per event of part 3")
    args = ap.parse_args()
    global VERBOSE
    VERBOSE = args.verbose
    analytic(args.seeds)
    simulated(args.duration)
    ratings(60, 20)
    cost(args.repeat)


if __name__ == "__main__":
    main()
