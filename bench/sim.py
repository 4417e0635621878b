"""Simulator benchmark: compiled fixed-step integrator vs scipy solve_ivp (LSODA), and Monte Carlo.

Run: ``.venv/bin/python bench/sim.py`` (single process; numba compiles once and caches to disk).

1. A 60 s drive log: torque at 100 Hz with jitter, alternating tip-ins and tip-outs, through the
   ``paper`` multibody model with housing. Real-time factor of the compiled run, as wall time and
   as this process's CPU time (the machine is shared: wall time includes waiting for a core);
   the same run at the previous step rule (0.3 x 2/|lambda|max) for comparison. JIT compile
   (first call in this process, loading from the on-disk cache if present) timed separately.
2. The same model in ``solve_ivp(method="LSODA")`` with a plain numpy right-hand side, on the first
   ``LSODA_SPAN`` s of the log (all of it would take minutes). Accuracy of both is measured
   against a tight reference (LSODA rtol 1e-10) on that span: p2p ripple error per event; the
   LSODA tolerance is the loosest whose error is not worse than ours ("matched accuracy").
   Speed-up = LSODA seconds per simulated second / ours.
3. 1000 Monte Carlo variants of a 2 s tip-in window over the tolerance bands.
1b. Real-time factor of that log through every preset (``--presets``: only this part).
1c. With ``--fit-runs``: the speed-only runs a fit makes (``simulate_speed(gaps=False)``), the generic
   compiled loop against the loop written out for the chain's layout (``sim.unrolled``), per preset and at 1x,
   2x and 8x the file's damping (identification moves it that far), CPU best of 5, interleaved; and whether
   the speeds are the same bit for bit.
4. With ``--scan``: the accuracy scan behind the step rule. Four tip-in scenarios against LSODA
   at rtol 1e-10 on a 10 us grid; for each step, the largest p2p-ripple and unloaded-time error.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

# This file is named like the package it measures: keep bench/ off the import path.
_HERE = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _HERE]
sys.path.insert(0, str(_HERE.parent))

import numpy as np  # noqa: E402

from sim import WhatIf, load_vehicle, simulate  # noqa: E402
from sim.batch import tolerance_analysis  # noqa: E402
from sim.linear import max_rate, step_limit  # noqa: E402
from sim.metrics import peak_to_valley, unloaded_time  # noqa: E402
from sim.model import build_chain  # noqa: E402
from sim.paper import tip_in_torque  # noqa: E402
from sim.reference import coupling_matrix, solve_reference  # noqa: E402
from sim.simulate import RPM  # noqa: E402

LSODA_SPAN = 6.0


def drive_log(duration: float = 60.0, seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """100 Hz torque with +-1 ms jitter: a tip-in/tip-out every 3 s between -60 and +160 N m."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, duration, 0.01) + rng.uniform(-1e-3, 1e-3, round(duration / 0.01))
    t[0] = 0.0
    t = np.sort(t)
    phase = (t % 3.0) / 3.0
    level = np.where(phase < 0.5, 160.0, -60.0)
    q = np.convolve(level, np.ones(12) / 12, mode="same")  # ~120 ms torque ramps
    q[:6] = level[0]
    q += rng.normal(0.0, 1.5, t.size)
    return t, q


def ripple_per_event(t: np.ndarray, speed: np.ndarray, period: float = 1.5) -> np.ndarray:
    edges = np.arange(0.25, t[-1], period)
    return np.array([peak_to_valley(t, speed, a, a + period) for a in edges])


def presets_realtime(t: np.ndarray, q: np.ndarray) -> None:
    """Real-time factor (CPU, best of 3) of the same 60 s drive log through every shipped topology."""
    from sim import Vehicle, preset_names

    chain = load_vehicle("chain_drive").to_dict()
    chain["stage"][-1]["right"] = {"stiffness": 8000.0, "damping": 2.0, "inertia": 0.003, "lash_rad": 0.004}
    cases = [(name, load_vehicle(name)) for name in preset_names()]
    cases.append(("chain_drive, unequal half-shafts", Vehicle.from_dict(chain)))
    print("[1b] real-time factor per preset (same log, CPU time, best of 3):")
    for name, v in cases:
        simulate(v, t[:50], q[:50])  # compile / cache load outside the timing
        cpus = []
        for _ in range(3):
            c1 = time.process_time()
            res = simulate(v, t, q)
            cpus.append(time.process_time() - c1)
        m = build_chain(v)
        print(f"    {name:<34} {m.n_bodies:2d} bodies, {len(v.gap_names)} gaps, step {res.dt * 1e6:6.1f} us: "
              f"{float(res.t[-1] - res.t[0]) / min(cpus):5.0f}x real time")


def fit_runs(t: np.ndarray, q: np.ndarray, repeats: int = 5) -> None:
    """Part 1c: a fit's speed-only run on the generic kernel loop against the written-out one, same run."""
    import sim.runner as runner
    from app.identify.base import stage_paths
    from sim import preset_names
    from sim.effects import apply_effects
    from sim.simulate import simulate_speed

    serial = runner.is_serial
    cases = [(name, load_vehicle(name)) for name in preset_names()]
    cases.append(("paper + tyre slip", apply_effects(load_vehicle("paper"), {"tyre_slip": {}})))
    cases.append(("paper + progressive shaft", apply_effects(load_vehicle("paper"), {"progressive_stiffness": {}})))
    print(f"[1c] a fit's speed-only run of the 60 s log: generic loop vs the loop written out per layout "
          f"(CPU, best of {repeats}, interleaved)")
    ratios = []
    for name, base in cases:
        for scale in (1.0, 2.0, 8.0):
            v = base.with_changes({p: float(base.get(p)) * scale for p in stage_paths(base, "damping")})
            best = {False: np.inf, True: np.inf}
            out = {}
            for rep in range(repeats + 1):  # the first round compiles or loads from the cache
                for written in (False, True):
                    runner.is_serial = serial if written else (lambda chain: False)
                    try:
                        c1 = time.process_time()
                        out[written] = simulate_speed(v, t, q, gaps=False).motor_speed_rpm
                        cpu = time.process_time() - c1
                    finally:
                        runner.is_serial = serial
                    if rep > 0:
                        best[written] = min(best[written], cpu)
            ratio = best[False] / best[True]
            ratios.append(ratio)
            same = np.array_equal(out[False], out[True])
            print(f"    {name:<28} damping x{scale:<3g} generic {best[False] * 1e3:7.1f} ms  written out "
                  f"{best[True] * 1e3:7.1f} ms  ratio {ratio:4.2f}  same speeds bit for bit: {'yes' if same else 'NO'}")
    print(f"    ratio median {np.median(ratios):.2f}, min {min(ratios):.2f}, max {max(ratios):.2f}")


def main() -> None:
    v = load_vehicle("paper")
    t, q = drive_log()
    w0 = v.body.speed_kmh / 3.6 / v.wheel.radius * v.ratio

    t_c = time.perf_counter()
    simulate(v, t[:50], q[:50])
    compile_s = time.perf_counter() - t_c
    old_dt = 0.3 * 2.0 / max_rate(build_chain(v))
    walls, cpus, old_cpus = [], [], []
    for _ in range(5):
        t1, c1 = time.perf_counter(), time.process_time()
        res = simulate(v, t, q)
        walls.append(time.perf_counter() - t1)
        cpus.append(time.process_time() - c1)
        c1 = time.process_time()
        old = simulate(v, t, q, dt=old_dt)
        old_cpus.append(time.process_time() - c1)
    ours_s, ours_cpu, old_cpu = min(walls), min(cpus), min(old_cpus)
    sim_span = float(res.t[-1] - res.t[0])
    print(f"[1] 60 s log, 100 Hz torque, multibody + housing ({len(build_chain(v).body_names)} bodies, "
          f"5 gaps), step {res.dt * 1e6:.1f} us")
    print(f"    JIT compile / cache load (first call): {compile_s:.2f} s")
    print(f"    run: {ours_s * 1e3:.1f} ms wall -> {sim_span / ours_s:.0f}x real time; "
          f"{ours_cpu * 1e3:.1f} ms CPU -> {sim_span / ours_cpu:.0f}x real time (best of 5)")
    print(f"    previous step rule (step {old.dt * 1e6:.1f} us): {old_cpu * 1e3:.1f} ms CPU -> "
          f"{sim_span / old_cpu:.0f}x real time; now {old_cpu / ours_cpu:.2f}x faster")

    presets_realtime(t, q)

    # --- 2. LSODA at matched accuracy on the first LSODA_SPAN seconds --------------------------
    m = build_chain(v)
    keep = t <= LSODA_SPAN + 0.02
    ts, qs = t[keep], q[keep]
    grid = np.arange(0.0, LSODA_SPAN + 1e-9, 1e-3)
    _, om_ref, _ = solve_reference(m, ts, qs, False, w0, grid, rtol=1e-10, atol=1e-10)
    ref = ripple_per_event(grid, (om_ref[:, m.rotor] - om_ref[:, m.housing]) * RPM)
    ours_short = simulate(v, ts, qs)
    n_ours = min(ours_short.t.size, grid.size)
    err_ours = np.abs(ripple_per_event(grid[:n_ours], ours_short.motor_speed_rpm[:n_ours]) - ref).max()
    print(f"[2] accuracy on the first {LSODA_SPAN:g} s vs LSODA rtol 1e-10: ours max p2p error {err_ours:.3f} rpm")
    chosen = None
    for rtol in (1e-4, 1e-5, 1e-6, 1e-7, 1e-8):
        t1 = time.perf_counter()
        _, om, nfev = solve_reference(m, ts, qs, False, w0, grid, rtol=rtol, atol=rtol * 1e-2)
        el = time.perf_counter() - t1
        err = np.abs(ripple_per_event(grid, (om[:, m.rotor] - om[:, m.housing]) * RPM) - ref).max()
        print(f"    LSODA rtol {rtol:.0e}: {el:.2f} s, {nfev} rhs calls, max p2p error {err:.3f} rpm")
        if err <= err_ours:
            chosen = (rtol, el)
            break
    if chosen is None:
        print("    no LSODA tolerance tried reached our accuracy; comparing with the tightest")
        chosen = (1e-8, el)
    lsoda_per_s = chosen[1] / LSODA_SPAN
    ours_per_s = ours_s / sim_span  # wall against wall: LSODA is timed the same way
    print(f"    matched accuracy (LSODA rtol {chosen[0]:.0e}): {lsoda_per_s:.3f} s per simulated s vs "
          f"ours {ours_per_s * 1e3:.2f} ms -> {lsoda_per_s / ours_per_s:.0f}x faster")

    # --- 3. Monte Carlo ------------------------------------------------------------------------
    tw, qw = tip_in_torque(duration_s=2.0)
    tolerance_analysis(v, tw, qw, n=5, interp="linear")  # compile the batch kernel
    t1 = time.perf_counter()
    tr = tolerance_analysis(v, tw, qw, n=1000, seed=1, interp="linear", window=(0.1, 0.6))
    mc_s = time.perf_counter() - t1
    lo, hi = tr.band()
    print(f"[3] 1000 Monte Carlo variants x 2 s tip-in: {mc_s:.2f} s "
          f"({2000.0 / mc_s:.0f}x real time overall)")
    print(f"    fluctuation 5-95 % band {lo:.0f}..{hi:.0f} rpm (nominal {tr.nominal_fluct_rpm:.0f} rpm); "
          f"unloaded time 5-95 % {np.percentile(tr.unloaded_ms, 5):.1f}..{np.percentile(tr.unloaded_ms, 95):.1f} ms")


def step_scan() -> None:
    """Largest p2p and unloaded-time errors over four tip-in scenarios, per integrator step."""
    base = load_vehicle("paper")
    scenarios = {"nominal": (base, 1.0), "half torque": (base, 0.5),
                 "half gaps": (WhatIf(gap_scale={"all": 0.5}).apply_vehicle(base), 1.0),
                 "1900 kg, 6000 N m/rad": (base.with_changes({"body.mass": 1900.0,
                                                             "halfshaft.stiffness": 6000.0}), 0.8)}
    subs = (20, 19, 17, 16, 15, 14, 13, 12, 11, 10, 9)
    errors: dict[int, list[tuple[float, float]]] = {n: [] for n in subs}
    limit = step_limit(build_chain(base))
    for v, scale in scenarios.values():
        t, q = tip_in_torque(scale, duration_s=0.45)
        m = build_chain(v)
        fine = np.arange(0.0, 0.45, 1e-5)
        w0 = v.body.speed_kmh / 3.6 / v.wheel.radius * v.ratio
        theta, omega, _ = solve_reference(m, t, q, True, w0, fine, rtol=1e-10, atol=1e-11)
        ref_speed = (omega[:, m.rotor] - omega[:, m.housing]) * RPM
        open_any = np.any(np.abs(theta @ coupling_matrix(m).T[:, :5]) < m.chalf[:5], axis=1)
        k0 = int(np.flatnonzero(open_any)[0])
        ref_ul = (int(np.argmin(open_any[k0:]))) * 1e-5
        w = (fine[k0] - 0.005, fine[k0] + 0.3)
        for n in subs:
            r = simulate(v, t, q, interp="linear", dt=1e-3 / n)
            ref = peak_to_valley(r.t, np.interp(r.t, fine, ref_speed), *w)
            errors[n].append((peak_to_valley(r.t, r.motor_speed_rpm, *w) - ref,
                              (unloaded_time(r.gap_events, 0.05) - ref_ul) * 1e3))
    print(f"[4] step scan, {len(scenarios)} tip-ins ({', '.join(scenarios)}) vs LSODA rtol 1e-10; "
          f"stability limit {limit * 1e6:.1f} us")
    for n in subs:
        e = np.abs(np.array(errors[n]))
        print(f"    step {1e3 / n:6.1f} us ({1e-3 / n / limit:.2f} of the limit): "
              f"max p2p error {e[:, 0].max():.3f} rpm, max unloaded-time error {e[:, 1].max():.3f} ms")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description="Simulator benchmark: compiled integrator vs solve_ivp (LSODA), Monte "
                                 "Carlo (parts 1-3 of the module docstring; the whole run takes a few minutes)")
    part = ap.add_mutually_exclusive_group()
    part.add_argument("--presets", action="store_true", help="only part 1b: real-time factor of every preset")
    part.add_argument("--scan", action="store_true", help="only part 4: the accuracy scan behind the step rule")
    part.add_argument("--fit-runs", action="store_true",
                      help="only part 1c: a fit's speed-only run, generic kernel loop vs the written-out one")
    args = ap.parse_args()
    if args.scan:
        step_scan()
    elif args.presets:
        presets_realtime(*drive_log())
    elif args.fit_runs:
        fit_runs(*drive_log())
    else:
        main()
