"""``lashscope reproduce-paper``, ``simulate`` (with what-ifs) and ``tolerance``: the simulator from the shell."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.errors import InputError

TOLERANCE_METRIC = ("largest peak-to-adjacent-valley of the raw motor speed in the event window (not detrended; "
                    "analyze's metrics are detrended)")
ONE_EVENT_S = 2.0  # an event window: 0.5 s before the crossing, 1.5 s after (app.analysis.events.EventParams)

if TYPE_CHECKING:  # numpy and the simulator (numba) are imported when a command runs, not for --help
    import numpy as np

    from sim.simulate import SimResult


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser("reproduce-paper", help="run the reference paper's cases and compare with its numbers")
    p.add_argument("--vehicle", default="paper_fitted",
                   help="preset name or TOML file (default: paper_fitted, the paper preset with the unpublished "
                        "inputs fitted to the paper's figures); its [tip_in] table, if any, is the tip-in torque")
    p.add_argument("--json", action="store_true", help="print one row per paper figure as JSON "
                                                       "(quantity, ours, paper, target, ok)")
    p.set_defaults(func=_reproduce)

    s = subparsers.add_parser("simulate", help="simulate motor speed from a torque CSV (columns t_s, torque_nm)")
    s.add_argument("torque_csv", type=Path, help="CSV with header t_s,torque_nm (irregular times allowed), or the "
                   "signals.csv of lashscope decode --map")
    s.add_argument("--vehicle", default="paper",
                   help="registered vehicle (lashscope init), preset name or TOML file (default: paper)")
    s.add_argument("--model", choices=("multibody", "two_inertia"), default="multibody")
    s.add_argument("--interp", choices=("hold", "linear"), default="hold")
    s.add_argument("--speed0-rpm", type=float, default=None, help="initial motor speed (default: from the vehicle)")
    s.add_argument("--output-dt", type=float, default=0.001, help="output grid spacing, s")
    s.add_argument("--out", type=Path, default=None, help="write t, speeds and gap states to this CSV")
    s.add_argument("--what-if", action="append", default=[], metavar="SPEC",
                   help="also run a what-if and compare with the baseline: comma-separated gap=NAME:FACTOR "
                        "(NAME a gap: a stage name on a [[stage]] vehicle, or 'all'; 0 removes it), torque=FACTOR, "
                        "anti_jerk=N_M_PER_S, "
                        "anti_jerk_band=N_M, set=dotted.field:VALUE; e.g. gap=halfshaft:0.5,torque=0.8,"
                        "anti_jerk=2000 (--out then holds the what-if run)")
    s.add_argument("--window", type=float, nargs=2, default=None, metavar=("T0", "T1"),
                   help="compare only the events whose torque crossing lies in T0..T1 s (without any there: the raw "
                        "speed's peak-to-adjacent-valley in the window)")
    s.set_defaults(func=_simulate)

    tol = subparsers.add_parser(
        "tolerance", help="Monte Carlo over the vehicle's tolerance bands: predicted ripple band for a torque CSV")
    tol.add_argument("torque_csv", type=Path, help="CSV with header t_s,torque_nm (irregular times allowed)")
    tol.add_argument("--vehicle", default="paper",
                     help="registered vehicle, preset name or TOML file with [min, max] bands")
    tol.add_argument("--n", type=int, default=1000, help="number of sampled variants (default 1000)")
    tol.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same band")
    tol.add_argument("--distribution", choices=("uniform", "normal"), default="uniform",
                     help="uniform over each band, or normal with the band as +-3 sigma")
    tol.add_argument("--window", type=float, nargs=2, default=None, metavar=("T0", "T1"),
                     help="time window (s) of the ripple metric (default: the whole input)")
    tol.add_argument("--measured-ripple", type=float, default=None, metavar="RPM",
                     help="a measured peak-to-valley ripple to place inside the predicted band")
    tol.add_argument("--interp", choices=("hold", "linear"), default="hold")
    tol.add_argument("--speed0-rpm", type=float, default=None, help="initial motor speed (default: from the vehicle)")
    tol.add_argument("--output-dt", type=float, default=0.001, help="output grid spacing, s")
    tol.add_argument("--json", action="store_true", help="print the result as JSON")
    tol.set_defaults(func=_tolerance)


def _reproduce(args: argparse.Namespace) -> int:
    from sim import load_vehicle
    from sim.paper import TipIn, format_table, load_tip_in, reproduce, sensitivity_table

    vehicle = load_vehicle(args.vehicle)
    tip_in = load_tip_in(args.vehicle)
    rows, cases = reproduce(vehicle, tip_in)
    if args.json:
        print(json.dumps([r.__dict__ for r in rows], indent=2))
    else:
        t = tip_in or TipIn()
        print(f"vehicle {vehicle.name}; tip-in {t.start_nm:g} -> {t.end_nm:g} N m over {t.ramp_s * 1e3:.0f} ms "
              f"from {t.t0_s:g} s{'' if tip_in else ' (default ramp)'}")
        print(format_table(rows))
        print()
        print("Sensitivity detail (dn = drop of the peak-valley fluctuation when the gap is eliminated):")
        print(sensitivity_table(vehicle, cases))
    return 0


def _read_torque(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Torque samples from a CSV with columns t_s,torque_nm, or from the long table ``lashscope decode --map``
    writes (channel,t_s,value,unit: the motor_torque_nm rows)."""
    import numpy as np

    if not path.is_file():
        raise InputError(f"torque file not found: {path}")
    with path.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        names = set(reader.fieldnames or ())
        long = {"channel", "t_s", "value"} <= names
        if not long and not {"t_s", "torque_nm"} <= names:
            raise InputError(f"{path}: needs a header with columns t_s,torque_nm (or channel,t_s,value from "
                             f"lashscope decode --map); found {reader.fieldnames}")
        t, q = [], []
        for line, row in enumerate(reader, start=2):
            if long and row["channel"] != "motor_torque_nm":
                continue
            try:
                t.append(float(row["t_s"]))
                q.append(float(row["value" if long else "torque_nm"]))
            except (TypeError, ValueError) as exc:
                raise InputError(f"{path}:{line}: not a number: {row}") from exc
    if long and not t:
        raise InputError(f"{path}: no motor_torque_nm rows in the decoded table")
    return np.asarray(t), np.asarray(q)


def _simulate(args: argparse.Namespace) -> int:
    from app.cli.vehicle_args import load_driveline
    from sim import simulate
    from sim.whatif import parse_what_if

    what_if = parse_what_if(args.what_if) if args.what_if else None  # bad specs fail before any work
    window = _check_window(args.window)
    t, q = _read_torque(args.torque_csv)
    vehicle = load_driveline(args.vehicle)
    if what_if is not None:  # unknown gaps, fields and oversize shaping too: before the baseline runs
        what_if.apply_vehicle(vehicle)
        what_if.apply_torque(t, q)
    res = simulate(vehicle, t, q, model=args.model, interp=args.interp, speed0_rpm=args.speed0_rpm,
                   output_dt=args.output_dt)
    print(f"vehicle {vehicle.name}, model {res.model}, {res.t[-1] - res.t[0]:.3f} s simulated, step {res.dt:.3g} s")
    runs = [("baseline" if what_if else "simulated", res)]
    if what_if is not None:
        alt = simulate(vehicle, t, q, model=args.model, interp=args.interp, speed0_rpm=args.speed0_rpm,
                       output_dt=args.output_dt, what_if=what_if)
        runs.append((f"what-if {','.join(args.what_if)}", alt))
    longest = [_summary(label, r) for label, r in runs]
    print()
    for line in ripple_lines(runs, window):
        print(line)
    if what_if is not None:
        print(_feel_change(runs[0][1], runs[1][1]))
        print(f"longest unloaded interval (any gap open): what-if {longest[1]:.1f} ms vs baseline {longest[0]:.1f} ms")
    res = runs[-1][1]
    if res.input_gaps:
        print(f"{len(res.input_gaps)} holes in the torque samples, first at {res.input_gaps[0][0]:.3f} s")
    if args.out is not None:
        cols = {"t_s": res.t, "motor_speed_rpm": res.motor_speed_rpm, "wheel_speed_rpm": res.wheel_speed_rpm,
                "vehicle_speed_kmh": res.vehicle_speed_kmh, "airgap_torque_nm": res.airgap_torque_nm}
        cols.update({f"torque_{k}_nm": v for k, v in res.coupling_torques.items()})
        cols.update({f"open_{k}": v.astype(int) for k, v in res.gap_open.items()})
        with args.out.open("w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            w.writerows(zip(*cols.values(), strict=True))
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


def _check_window(window: list[float] | None) -> tuple[float, float] | None:
    if window is None:
        return None
    t0, t1 = (float(v) for v in window)
    if not (t0 == t0 and t1 == t1) or not t1 > t0:  # NaN or empty
        raise InputError(f"--window {t0:g} {t1:g}: needs T0 < T1 (s)")
    return t0, t1


def ripple_lines(runs: list[tuple[str, SimResult]], window: tuple[float, float] | None) -> list[str]:
    """The ripple of each run per tip-in/tip-out event of the torque (and the median), as text.

    Events come from the first run's torque and speed; each run is detrended with its own torque
    (:mod:`app.analysis.whatif`). ``window`` keeps the events whose crossing lies in it; without any
    event there, the ripple is the raw peak-to-adjacent-valley in the window, said so.
    """
    import numpy as np

    from app.analysis.whatif import Run, event_ripples, median_ratio, medians, torque_events
    from sim.metrics import peak_to_valley

    base = runs[0][1]
    events = torque_events(base.t, base.airgap_torque_nm, base.motor_speed_rpm)
    if window is not None:
        events = [e for e in events if window[0] <= e.t_cross_s <= window[1]]
    labels = [label.split(" ", 1)[0] for label, _ in runs]
    if not events:
        span = float(base.t[-1] - base.t[0])
        if window is None and span > ONE_EVENT_S:
            return ["ripple: no tip-in or tip-out in the torque input (a reversal through 0 N m held for 80 ms "
                    "each side), so no ripple to compare; give --window T0 T1 to compare the raw speed there"]
        why = "no tip-in or tip-out there"
        if window is None:  # a single manoeuvre (e.g. the paper's tip-in): the input is one event window
            window, why = (float(base.t[0]), float(base.t[-1])), f"the whole input, {span:.2f} s: one event at most"
        vals = [peak_to_valley(r.t, r.motor_speed_rpm, *window) for _, r in runs]
        lines = [f"ripple in the window {window[0]:g}..{window[1]:g} s ({why}): largest "
                 "peak-to-adjacent-valley of the raw motor speed, not detrended (a speed swing of the drive counts)"]
        lines += [f"  {label}: {v:.1f} rpm" for label, v in zip(labels, vals, strict=True)]
        if len(vals) > 1 and vals[0] > 0:
            lines.append(f"what-if ripple {vals[1]:.1f} rpm = {100.0 * vals[1] / vals[0]:.0f} % of the baseline's "
                         f"{vals[0]:.1f} rpm (raw, in the window)")
        return lines
    rows = event_ripples([Run(label, r.t, r.motor_speed_rpm, r.airgap_torque_nm) for label, r in runs], events)

    def num(v: float) -> str:
        return f"{v:.1f}" if np.isfinite(v) else "-"

    lines = ["ripple per event: peak-to-adjacent-valley fluctuation of the motor speed detrended from the "
             "rigid-body trend, in the event window (as analyze's metrics); - = no impact peak and valley",
             f"{'#':>3} {'kind':<8} {'t (s)':>7} {'window (s)':>13} "
             + " ".join(f"{f'{lab} (rpm)':>15}" for lab in labels)
             + (f" {'what-if/baseline':>16}" if len(runs) > 1 else "")]
    for r in rows:
        f = r.fluctuation_rpm
        ratio = f"{100.0 * f[1] / f[0]:.0f} %" if len(f) > 1 and np.isfinite(f[0] * f[1]) and f[0] > 0 else "-"
        lines.append(f"{r.index:>3} {r.kind:<8} {r.t_cross_s:>7.2f} {f'{r.t_start_s:.2f}..{r.t_end_s:.2f}':>13} "
                     + " ".join(f"{num(v):>15}" for v in f) + (f" {ratio:>16}" if len(f) > 1 else ""))
    med = medians(rows, len(runs))
    where = f" with a crossing in {window[0]:g}..{window[1]:g} s" if window is not None else ""
    text = ", ".join(f"{lab} {num(m)} rpm" for lab, m in zip(labels, med, strict=True))
    lines.append(f"median over {len(rows)} events{where}: {text}")
    if len(runs) > 1 and np.isfinite(med[0] * med[1]) and med[0] > 0:
        per = median_ratio(rows, 0, 1)
        lines.append(f"what-if ripple (median over events) {med[1]:.1f} rpm = {100.0 * med[1] / med[0]:.0f} % of the "
                     f"baseline's {med[0]:.1f} rpm (ratio of the medians; median of the per-event ratios "
                     f"{'-' if not np.isfinite(per) else f'{100.0 * per:.0f} %'})")
    return lines


def _feel_change(base: SimResult, alt: SimResult) -> str:
    """What the occupants feel, baseline -> what-if: body acceleration criteria around the torque reversal."""
    from app.analysis.feel import run_feel

    a = run_feel(base.t, base.vehicle_accel_ms2, base.airgap_torque_nm)
    b = run_feel(alt.t, alt.vehicle_accel_ms2, alt.airgap_torque_nm)

    def pair(x: float, y: float, fmt: str) -> str:
        return f"{format(x, fmt) if x == x else '-'} -> {format(y, fmt) if y == y else '-'}"

    return (f"felt (body acceleration, baseline -> what-if): shuffle peak-to-peak "
            f"{pair(a.shuffle_pp_ms2, b.shuffle_pp_ms2, '.2f')} m/s^2, kick {pair(a.kick_ms2, b.kick_ms2, '.2f')} "
            f"m/s^2, max jerk {pair(a.max_jerk_ms3, b.max_jerk_ms3, '.1f')} m/s^3, VDV "
            f"{pair(a.vdv_ms175, b.vdv_ms175, '.2f')} m/s^1.75")


def _felt_band(res: Any, t: Any, q: Any) -> dict[str, float | None]:
    """Shuffle peak-to-peak (m/s^2) of the nominal run and its 5/50/95 % band over the variants
    (:func:`app.analysis.feel.run_feel` on each run's body acceleration); None where not determinable."""
    import numpy as np

    from app.analysis.feel import run_feel

    if res.t is None or res.vehicle_speed_kmh is None:
        return {"nominal": None, "p5": None, "p50": None, "p95": None}
    torque = np.interp(res.t, t, q)
    pp = np.array([run_feel(res.t, np.gradient(v / 3.6, res.t), torque).shuffle_pp_ms2
                   for v in res.vehicle_speed_kmh])
    fin = pp[1:][np.isfinite(pp[1:])]
    band = np.percentile(fin, [5.0, 50.0, 95.0]) if fin.size else [None] * 3
    return {"nominal": float(pp[0]) if np.isfinite(pp[0]) else None,
            **{k: (None if v is None else float(v)) for k, v in zip(("p5", "p50", "p95"), band, strict=True)}}


def _summary(label: str, res: SimResult) -> float:
    """Print one run's speed range and unloaded intervals; return the longest unloaded interval (ms)."""
    from sim.metrics import unloaded_intervals

    spans = unloaded_intervals(res.gap_events, float(res.t[-1]))
    longest = max((b - a for a, b in spans), default=0.0) * 1e3
    print(f"{label}: motor speed {res.motor_speed_rpm.min():.1f}..{res.motor_speed_rpm.max():.1f} rpm; "
          f"{len(spans)} unloaded intervals (any gap open), longest {longest:.1f} ms")
    return longest


def _tolerance(args: argparse.Namespace) -> int:
    import numpy as np

    from app.cli.vehicle_args import load_driveline
    from sim.batch import tolerance_analysis

    window = _check_window(args.window)
    t, q = _read_torque(args.torque_csv)
    vehicle = load_driveline(args.vehicle)
    if window is None:
        from app.analysis.whatif import torque_events
        from sim import simulate

        base = simulate(vehicle, t, q, interp=args.interp, speed0_rpm=args.speed0_rpm, output_dt=args.output_dt)
        events = torque_events(base.t, base.airgap_torque_nm, base.motor_speed_rpm)
        if events:
            return _tolerance_per_event(args, vehicle, t, q, base, events)
        if float(t[-1] - t[0]) > ONE_EVENT_S:
            raise InputError("tolerance: no tip-in or tip-out in the torque input (a reversal through 0 N m held "
                             "80 ms each side) and no --window: a ripple over the whole input would be a speed swing "
                             "of the drive; give --window T0 T1", code="no_events")

    def progress(done: int, total: int) -> None:
        print(f"tolerance: {done}/{total} variants", file=sys.stderr, flush=True)

    res = tolerance_analysis(vehicle, t, q, n=args.n, seed=args.seed, distribution=args.distribution,
                             window=window, interp=args.interp,
                             speed0_rpm=args.speed0_rpm, output_dt=args.output_dt, progress=progress,
                             body_speed=True)
    p5, p50, p95 = (float(v) for v in np.percentile(res.fluct_rpm, [5.0, 50.0, 95.0]))
    felt = _felt_band(res, t, q)
    u5, u50, u95 = (float(v) for v in np.percentile(res.unloaded_ms, [5.0, 50.0, 95.0]))
    out: dict[str, object] = {
        "vehicle": vehicle.name, "n": args.n, "seed": args.seed, "distribution": args.distribution,
        "fields": list(res.fields), "nominal_ripple_rpm": res.nominal_fluct_rpm,
        "ripple_rpm": {"p5": p5, "p50": p50, "p95": p95},
        "unloaded_ms": {"p5": u5, "p50": u50, "p95": u95},
        "shuffle_pp_ms2": felt,
    }
    pct = res.percentile_of(args.measured_ripple) if args.measured_ripple is not None else None
    if pct is not None:
        out["measured_ripple_rpm"] = args.measured_ripple
        out["measured_percentile"] = pct
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"vehicle {vehicle.name}: {args.n} variants ({args.distribution}, seed {args.seed}) over "
          f"{', '.join(res.fields)}")
    where = f"in {window[0]:g}..{window[1]:g} s" if window is not None else "over the whole input (one event)"
    print(f"ripple (largest peak-to-adjacent-valley of the raw motor speed {where}, not detrended): nominal "
          f"{res.nominal_fluct_rpm:.1f} rpm; predicted 5 % {p5:.1f}, 50 % {p50:.1f}, 95 % {p95:.1f} rpm")
    print(f"first unloaded interval: 5 % {u5:.1f}, 50 % {u50:.1f}, 95 % {u95:.1f} ms")
    if felt["p50"] is not None:
        nom = "-" if felt["nominal"] is None else f"{felt['nominal']:.2f}"
        print(f"felt shuffle peak-to-peak (body acceleration): nominal {nom} m/s^2; predicted "
              f"5 % {felt['p5']:.2f}, 50 % {felt['p50']:.2f}, 95 % {felt['p95']:.2f} m/s^2")
    if pct is not None:
        where = "below the band" if args.measured_ripple < p5 else "above the band" if args.measured_ripple > p95 \
            else "inside the 5-95 % band"
        print(f"measured ripple {args.measured_ripple:.1f} rpm: percentile {pct:.1f} of the prediction ({where})")
    return 0


def _tolerance_per_event(args: argparse.Namespace, vehicle: Any, t: np.ndarray, q: np.ndarray, base: SimResult,
                         events: list[Any]) -> int:
    """The Monte Carlo per tip-in/tip-out event of the torque: each event window simulated from just before it
    (at the nominal run's speed there), its ripple band, and the median over the events."""
    import numpy as np

    from sim.batch import tolerance_analysis, tolerance_sample

    lead = 0.05  # s simulated before the window, as the analysis' tolerance band
    sample = tolerance_sample(vehicle, args.n, args.seed, args.distribution)  # every event runs these, built once
    rows: list[dict[str, Any]] = []
    fields: tuple[str, ...] = ()
    for k, ev in enumerate(events):
        m = (t >= ev.t_start_s - lead) & (t <= ev.t_end_s)
        if int(m.sum()) < 2:
            continue

        def progress(done: int, total: int, k: int = k) -> None:
            print(f"tolerance: event {k + 1}/{len(events)}: {done}/{total} variants", file=sys.stderr, flush=True)

        speed0 = float(np.interp(t[m][0], base.t, base.motor_speed_rpm))
        res = tolerance_analysis(vehicle, t[m], q[m], n=args.n, seed=args.seed, distribution=args.distribution,
                                 window=(ev.t_start_s, ev.t_end_s), interp=args.interp, speed0_rpm=speed0,
                                 output_dt=args.output_dt, progress=progress, sample=sample)
        fields = res.fields
        p5, p50, p95 = (float(v) for v in np.percentile(res.fluct_rpm, [5.0, 50.0, 95.0]))
        row: dict[str, Any] = {"index": ev.index, "kind": ev.kind.value, "t_cross_s": ev.t_cross_s,
                               "t_start_s": ev.t_start_s, "t_end_s": ev.t_end_s,
                               "nominal_ripple_rpm": res.nominal_fluct_rpm,
                               "ripple_rpm": {"p5": p5, "p50": p50, "p95": p95},
                               "unloaded_ms_median": float(np.median(res.unloaded_ms))}
        if args.measured_ripple is not None:
            row["measured_percentile"] = res.percentile_of(args.measured_ripple)
        rows.append(row)
    med = {key: float(np.median([r["ripple_rpm"][key] for r in rows])) for key in ("p5", "p50", "p95")}
    nominal = float(np.median([r["nominal_ripple_rpm"] for r in rows]))
    out: dict[str, Any] = {"vehicle": vehicle.name, "n": args.n, "seed": args.seed, "distribution": args.distribution,
                           "fields": list(fields), "metric": TOLERANCE_METRIC, "events": rows,
                           "median_over_events": {"nominal_ripple_rpm": nominal, "ripple_rpm": med}}
    if args.measured_ripple is not None:
        out["measured_ripple_rpm"] = args.measured_ripple
    if args.json:
        print(json.dumps(out, indent=2))
        return 0
    print(f"vehicle {vehicle.name}: {args.n} variants per event ({args.distribution}, seed {args.seed}) over "
          f"{', '.join(fields)}")
    print(f"ripple per event: {TOLERANCE_METRIC}")
    head = f"{'#':>3} {'kind':<8} {'t (s)':>7} {'window (s)':>13} {'nominal':>8} {'p5':>8} {'p50':>8} {'p95':>8}"
    print(head + (f" {'measured pct':>12}" if args.measured_ripple is not None else "") + "   (rpm)")
    for r in rows:
        b = r["ripple_rpm"]
        pct = f" {r['measured_percentile']:>11.1f}%" if "measured_percentile" in r else ""
        span = f"{r['t_start_s']:.2f}..{r['t_end_s']:.2f}"
        print(f"{r['index']:>3} {r['kind']:<8} {r['t_cross_s']:>7.2f} {span:>13} {r['nominal_ripple_rpm']:>8.1f} "
              f"{b['p5']:>8.1f} {b['p50']:>8.1f} {b['p95']:>8.1f}{pct}")
    print(f"median over {len(rows)} events (of each column): nominal {nominal:.1f} rpm; predicted 5 % "
          f"{med['p5']:.1f}, 50 % {med['p50']:.1f}, 95 % {med['p95']:.1f} rpm")
    return 0
