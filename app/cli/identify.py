"""``lashscope identify LOG [LOG...] --vehicle V --out V_identified.toml [--validate OTHER]``: learn the car.

Decodes the logs, estimates the first torsional mode model-free from every tip-in/tip-out window,
fits the vehicle file's identifiable base parameters (stiffness, damping, mass, total lash, with
torque gain and road load) with intervals, says which ones the data do not pin down, optionally
checks the identified vehicle on a withheld drive, and writes it as a new vehicle file with its
provenance. Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli.diagnose import _progress
from app.cli.log_args import add_format_file, log_help
from app.cli.report import identified_param
from app.cli.vehicle_args import add_vehicle, event_params, vehicle_inputs


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "identify", help="identify the vehicle's base parameters from its own logs",
        description="Estimate the first torsional mode of the driveline from the tip-in/tip-out windows of the logs "
        "and fit the vehicle file's identifiable base parameters (torsional stiffness, damping, vehicle mass, total "
        "lash; torque gain and road load) with intervals; write the identified vehicle as a new file.")
    p.add_argument("logs", type=Path, nargs="+", metavar="LOG", help=log_help("CAN logs of the same car"))
    add_format_file(p)
    add_vehicle(p)
    p.add_argument("--out", type=Path, default=None, metavar="TOML",
                   help="write the identified vehicle here (default: <vehicle>_identified.toml in the working "
                        "directory)")
    p.add_argument("--name", default=None, help="name of the identified vehicle (default: the file's name)")
    p.add_argument("--validate", type=Path, action="append", default=[], metavar="OTHER_LOG",
                   help="a withheld drive: tracking verdict and NRMSE with the file's and the identified vehicle "
                        "(repeatable)")
    p.add_argument("--params", default=None,
                   help="comma-separated base parameters to fit (default: stiffness,damping,mass,lash)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--model", choices=["multibody", "two_inertia"], default="multibody")
    p.add_argument("--json", action="store_true", help="print the JSON result instead of the summary")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def summary(doc: dict[str, Any], out: Path | None) -> str:
    lines = [f"vehicle {doc['vehicle']}: {doc['events']} events from "
             + ", ".join(f"{lg['name']} ({lg['events']})" for lg in doc["logs"])]
    m = doc.get("modal")
    if m:
        lines.append(f"first mode (model-free, {m['n_used']} of {m['n_windows']} windows): {m['freq_hz']:.2f} Hz "
                     f"[{m['freq_ci'][0]:.2f}, {m['freq_ci'][1]:.2f}], damping ratio {m['zeta']:.3f} "
                     f"[{m['zeta_ci'][0]:.3f}, {m['zeta_ci'][1]:.3f}]")
    else:
        lines.append(f"first mode (model-free): none ({doc.get('modal_error')})")
    if doc.get("rigid_body"):
        lines.append(doc["rigid_body"]["summary"])
    lines.append("")
    width = max(len(p["label"]) for p in doc["params"].values())
    for p in doc["params"].values():
        lines.append(f"{p['label']:{width}s}  {identified_param(p)}")
    lines.append(f"\nresidual / noise on the fitted events: {doc['residual_to_noise_before']:.2f} with the file, "
                 f"{doc['residual_to_noise_after']:.2f} identified")
    form = doc.get("contact_damping")
    if form:
        res = ", ".join(f"{law} {x:.2f}" for law, x in form["residual_to_noise"].items())
        lines.append(f"contact damping: {form['contact_damping']}"
                     + (f" (the file says {form['file']}; the new version carries it)" if form["changed"] else
                        " (as the file)") + f"; residual / noise under each law: {res}")
    v = doc.get("validation")
    if v:
        lines.append(f"withheld drive: NRMSE {v['nrmse_before']} -> {v['nrmse_after']} (median over events), "
                     f"tracking {v['verdict_before']} -> {v['verdict_after']}")
    named = doc["named"]
    lines.append("off the file: " + (", ".join(named) if named else "nothing (every interval holds the file's value "
                                     "or the change is too small to matter)"))
    gain = doc["params"].get("torque_gain") or {}
    if doc.get("torque_gain_written") is not None:
        lines.append(f"the logged torque reads {1.0 / gain['ratio']:.3g}x the air-gap torque: the new version carries "
                     f"torque_gain = {gain['value']:.4g} (file {gain['nominal']:.4g})")
    if out is not None:
        lines.append(f"identified vehicle written to {out}")
    lines.append(f"{doc['elapsed_s']:.1f} s CPU")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
    from app.errors import InputError
    from app.identify import BASE_NAMES
    from app.identify.logs import IdentifyOptions, identify_logs
    from app.pipeline import VehicleInputs

    params = BASE_NAMES if args.params is None else tuple(x.strip() for x in args.params.split(",") if x.strip())
    unknown = [x for x in params if x not in BASE_NAMES]
    if unknown or not params:
        raise InputError(f"--params {args.params!r}: known base parameters are {', '.join(BASE_NAMES)}")
    thresholds = event_params(args, DIAGNOSIS_EVENTS)
    inputs: VehicleInputs = vehicle_inputs(args)
    options = IdentifyOptions(dbc=inputs.database, signal_map=inputs.signal_map, seed=args.seed, params=params,
                              model=args.model, events=thresholds)
    result = identify_logs(args.logs, inputs.vehicle, options, args.validate, _progress(args.quiet))
    out = args.out or Path(f"{inputs.vehicle.name}_identified.toml")
    out.write_text(result.vehicle_toml(args.name), encoding="utf-8")
    doc = result.to_dict()
    doc["out"] = str(out)
    sys.stdout.write(json.dumps(doc, indent=1, allow_nan=False) + "\n" if args.json else summary(doc, out) + "\n")
    return 0
