"""``lashscope reproduce-paper`` and ``lashscope simulate``: the driveline simulator from the shell."""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from app.errors import InputError

if TYPE_CHECKING:  # numpy and the simulator (numba) are imported when a command runs, not for --help
    import numpy as np


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser("reproduce-paper", help="run the reference paper's cases and compare with its numbers")
    p.add_argument("--vehicle", default="paper", help="preset name or TOML file (default: paper)")
    p.add_argument("--json", action="store_true", help="print rows as JSON")
    p.set_defaults(func=_reproduce)

    s = subparsers.add_parser("simulate", help="simulate motor speed from a torque CSV (columns t_s, torque_nm)")
    s.add_argument("torque_csv", type=Path, help="CSV with header t_s,torque_nm (irregular times allowed)")
    s.add_argument("--vehicle", default="paper", help="preset name or TOML file (default: paper)")
    s.add_argument("--model", choices=("multibody", "two_inertia"), default="multibody")
    s.add_argument("--interp", choices=("hold", "linear"), default="hold")
    s.add_argument("--speed0-rpm", type=float, default=None, help="initial motor speed (default: from the vehicle)")
    s.add_argument("--output-dt", type=float, default=0.001, help="output grid spacing, s")
    s.add_argument("--out", type=Path, default=None, help="write t, speeds and gap states to this CSV")
    s.set_defaults(func=_simulate)


def _reproduce(args: argparse.Namespace) -> int:
    from sim import load_vehicle
    from sim.paper import format_table, reproduce, sensitivity_table

    vehicle = load_vehicle(args.vehicle)
    rows, cases = reproduce(vehicle)
    if args.json:
        print(json.dumps([r.__dict__ for r in rows], indent=2))
    else:
        print(format_table(rows))
        print()
        print("Sensitivity detail (dn = drop of the impact-induced fluctuation when the gap is eliminated):")
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
    from sim.metrics import peak_to_valley, unloaded_intervals

    t, q = _read_torque(args.torque_csv)
    vehicle = load_vehicle(args.vehicle)
    res = simulate(vehicle, t, q, model=args.model, interp=args.interp, speed0_rpm=args.speed0_rpm,
                   output_dt=args.output_dt)
    spans = unloaded_intervals(res.gap_events, float(res.t[-1]))
    print(f"vehicle {vehicle.name}, model {res.model}, {res.t[-1] - res.t[0]:.3f} s simulated, step {res.dt:.3g} s")
    print(f"motor speed {res.motor_speed_rpm.min():.1f}..{res.motor_speed_rpm.max():.1f} rpm, "
          f"largest peak-to-valley {peak_to_valley(res.t, res.motor_speed_rpm):.1f} rpm")
    print(f"{len(spans)} unloaded intervals (any gap open); longest "
          f"{max((b - a for a, b in spans), default=0.0) * 1e3:.1f} ms")
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
