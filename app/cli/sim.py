"""``lashscope reproduce-paper``, ``simulate`` (with what-ifs) and ``tolerance``: the simulator from the shell."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.errors import InputError

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
    s.add_argument("torque_csv", type=Path, help="CSV with header t_s,torque_nm (irregular times allowed)")
    s.add_argument("--vehicle", default="paper", help="preset name or TOML file (default: paper)")
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
    s.set_defaults(func=_simulate)

    tol = subparsers.add_parser(
        "tolerance", help="Monte Carlo over the vehicle's tolerance bands: predicted ripple band for a torque CSV")
    tol.add_argument("torque_csv", type=Path, help="CSV with header t_s,torque_nm (irregular times allowed)")
    tol.add_argument("--vehicle", default="paper", help="preset name or TOML file with [min, max] bands")
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
    import numpy as np

    if not path.is_file():
        raise InputError(f"torque file not found: {path}")
    with path.open(newline="", encoding="utf-8") as fh:
        reader = csv.DictReader(fh)
        if reader.fieldnames is None or not {"t_s", "torque_nm"} <= set(reader.fieldnames):
            raise InputError(f"{path}: needs a header with columns t_s,torque_nm; found {reader.fieldnames}")
        t, q = [], []
        for line, row in enumerate(reader, start=2):
            try:
                t.append(float(row["t_s"]))
                q.append(float(row["torque_nm"]))
            except (TypeError, ValueError) as exc:
                raise InputError(f"{path}:{line}: not a number: {row}") from exc
    return np.asarray(t), np.asarray(q)


def _simulate(args: argparse.Namespace) -> int:
    from sim import load_vehicle, simulate
    from sim.whatif import parse_what_if

    what_if = parse_what_if(args.what_if) if args.what_if else None  # bad specs fail before any work
    t, q = _read_torque(args.torque_csv)
    vehicle = load_vehicle(args.vehicle)
    res = simulate(vehicle, t, q, model=args.model, interp=args.interp, speed0_rpm=args.speed0_rpm,
                   output_dt=args.output_dt)
    print(f"vehicle {vehicle.name}, model {res.model}, {res.t[-1] - res.t[0]:.3f} s simulated, step {res.dt:.3g} s")
    base = _summary("baseline" if what_if else "", res)
    if what_if is not None:
        alt = simulate(vehicle, t, q, model=args.model, interp=args.interp, speed0_rpm=args.speed0_rpm,
                       output_dt=args.output_dt, what_if=what_if)
        new = _summary(f"what-if {','.join(args.what_if)}", alt)
        if base[0] > 0:
            print(f"what-if ripple {new[0]:.1f} rpm = {100.0 * new[0] / base[0]:.0f} % of the baseline's "
                  f"{base[0]:.1f} rpm; longest unloaded interval {new[1]:.1f} ms vs {base[1]:.1f} ms")
        print(_feel_change(res, alt))
        res = alt
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


def _summary(label: str, res: SimResult) -> tuple[float, float]:
    """Print one run's speed range, ripple and unloaded intervals; return (ripple rpm, longest unloaded ms)."""
    from sim.metrics import peak_to_valley, unloaded_intervals

    spans = unloaded_intervals(res.gap_events, float(res.t[-1]))
    ripple = peak_to_valley(res.t, res.motor_speed_rpm)
    longest = max((b - a for a, b in spans), default=0.0) * 1e3
    prefix = f"{label}: " if label else ""
    print(f"{prefix}motor speed {res.motor_speed_rpm.min():.1f}..{res.motor_speed_rpm.max():.1f} rpm, "
          f"largest peak-to-valley {ripple:.1f} rpm")
    print(f"{prefix}{len(spans)} unloaded intervals (any gap open); longest {longest:.1f} ms")
    return ripple, longest


def _tolerance(args: argparse.Namespace) -> int:
    import numpy as np

    from sim import load_vehicle
    from sim.batch import tolerance_analysis

    t, q = _read_torque(args.torque_csv)
    vehicle = load_vehicle(args.vehicle)

    def progress(done: int, total: int) -> None:
        print(f"tolerance: {done}/{total} variants", file=sys.stderr, flush=True)

    res = tolerance_analysis(vehicle, t, q, n=args.n, seed=args.seed, distribution=args.distribution,
                             window=tuple(args.window) if args.window else None, interp=args.interp,
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
    print(f"ripple (largest peak-to-valley of motor speed): nominal {res.nominal_fluct_rpm:.1f} rpm; "
          f"predicted 5 % {p5:.1f}, 50 % {p50:.1f}, 95 % {p95:.1f} rpm")
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
