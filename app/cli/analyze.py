"""``lashscope analyze LOG --vehicle V``: the same pipeline as the API, in-process, JSON out."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

from app.cli.vehicle_args import add_log_and_vehicle, event_params, resolve_vehicle


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "analyze", help="analyse a log: events, simulation, metrics",
        description="Decode LOG with the DBC and signal map, find tip-in/tip-out events, simulate the vehicle "
        "with the measured torque and compare ripple metrics.")
    add_log_and_vehicle(p)
    p.add_argument("--model", choices=["multibody", "two_inertia"], default="multibody")
    p.add_argument("--no-whole-log", action="store_true", help="skip the open-loop whole-log simulation")
    p.add_argument("--gap-sensitivity", action="store_true",
                   help="add the vehicle's gap what-ifs and sensitivities S1..S5 (paper tip-in, ~2 s)")
    p.add_argument("--tolerance", type=int, default=0, metavar="N",
                   help="add the predicted ripple band (5/50/95 %%) over the vehicle's tolerance bands, N Monte "
                   "Carlo variants per event, and each measured ripple's percentile in it")
    p.add_argument("--seed", type=int, default=0, help="random seed of --tolerance (default 0)")
    p.add_argument("--ratings", type=Path, default=None, metavar="MODEL",
                   help="score every event with a fitted rating model (lashscope ratings fit); "
                   "default: LASHSCOPE_RATINGS, else no rating")
    p.add_argument("--json", action="store_true", help="print the full result as JSON")
    p.add_argument("--out", type=Path, default=None, help="also write the JSON result to this file")
    p.set_defaults(func=run)


def analysis_doc(args: argparse.Namespace) -> dict[str, Any]:
    from app.fleet.hook import after_analysis, store_dir
    from app.payload import result_payload
    from app.pipeline import AnalysisOptions, run_analysis
    from app.storage.results import json_safe

    inputs, vehicle_name = resolve_vehicle(args)
    opts = AnalysisOptions(model=args.model, whole_log=not args.no_whole_log, events=event_params(args))
    ratings = None
    if getattr(args, "ratings", None) is not None:
        from app.ratings_file import load_model

        ratings = load_model(args.ratings)  # a bad model file fails before the analysis runs
    result = run_analysis(args.log, inputs, opts)
    doc, arrays = result_payload(result, ratings)
    if ratings is None:
        after_analysis(args.log, inputs, doc)
    elif store_dir() is not None:  # the event rows carry LASHSCOPE_RATINGS's rating, not --ratings'
        after_analysis(args.log, inputs, result_payload(result)[0])
    if getattr(args, "tolerance", 0):
        from types import SimpleNamespace

        from app.pipeline import tolerance_for_result

        stored = SimpleNamespace(doc=doc, array=arrays.__getitem__)  # the result as the job reads it from disk
        doc["tolerance"] = tolerance_for_result(stored, inputs.vehicle, args.tolerance, getattr(args, "seed", 0))
    doc["log"] = str(args.log)
    doc["vehicle"] = vehicle_name
    if getattr(args, "gap_sensitivity", False):
        from app.pipeline import gap_sensitivity

        doc["gap_sensitivity"] = gap_sensitivity(inputs.vehicle)
    return dict(json_safe(doc))


def gap_sensitivity_table(sens: dict[str, Any]) -> str:
    """The gap what-ifs as text; the sensitivity columns name their unit (per mm of clearance, per rad)."""
    unit = sens["sensitivity_unit"]

    def num(v: float | None, fmt: str) -> str:
        return "-" if v is None or v != v else format(v, fmt)

    lines = [f"gap sensitivity, {sens['scenario']}; S = impact-fluctuation change per {unit} of gap "
             f"({'circumferential clearance' if unit == 'mm' else 'angle in its own shaft'}), halfshaft = 100",
             f"{'gap':<13} {'angle (rad)':>11} {'arc (mm)':>8} {'S per mm':>8} {'S per rad':>9} "
             f"{'impact, removed (rpm)':>21} {'halved (rpm)':>12}"]
    for g in sens["gaps"]:
        lines.append(f"{g['gap']:<13} {g['nominal_rad']:>11.4f} {num(g['clearance_mm'], '.3f'):>8} "
                     f"{num(g['sensitivity_per_mm'], '.1f'):>8} {g['sensitivity_per_rad']:>9.1f} "
                     f"{g['removed']['impact_rpm']:>21.1f} {g['halved']['impact_rpm']:>12.1f}")
    nom, zero = sens["nominal"], sens["zero_gaps"]
    lines.append(f"nominal: impact-induced fluctuation {nom['impact_rpm']:.1f} rpm, fluctuation "
                 f"{nom['fluctuation_rpm']:.1f} rpm; no backlash at all: fluctuation {zero['fluctuation_rpm']:.1f} rpm")
    if "shuffle_pp_ms2" in nom:
        lines.append("felt (body acceleration): shuffle peak-to-peak nominal "
                     f"{num(nom['shuffle_pp_ms2'], '.2f')} m/s^2, no backlash {num(zero['shuffle_pp_ms2'], '.2f')}; "
                     + "; ".join(f"{g['gap']} halved {num(g['halved'].get('shuffle_pp_ms2'), '.2f')}, removed "
                                 f"{num(g['removed'].get('shuffle_pp_ms2'), '.2f')}" for g in sens["gaps"]))
    if unit == "rad":
        lines.append("(per mm needs every gap's contact radius, gaps.<gap>.radius_mm, in the driveline file)")
    return "\n".join(lines)


def tolerance_table(tol: dict[str, Any]) -> str:
    """The tolerance band per event as text."""

    def num(v: float | None, fmt: str = ".1f") -> str:
        return "-" if v is None or v != v else format(v, fmt)

    lines = [f"tolerance band, {tol['n']} variants per event (seed {tol['seed']}); {tol['metric']}; felt: "
             f"{tol.get('felt_metric', '-')}",
             f"{'#':>3} {'kind':<8} {'p5':>8} {'p50':>8} {'p95':>8} {'nominal':>8} {'measured':>9} {'pct':>6} "
             f"{'detrended':>10}   {'p-p p5-p95':>12} {'measured':>8}",
             f"{'':>3} {'':<8} {'rpm':>8} {'rpm':>8} {'rpm':>8} {'rpm':>8} {'raw, rpm':>9} {'':>6} {'meas., rpm':>10}"
             f"   {'m/s^2':>12} {'m/s^2':>8}"]
    for e in tol["events"]:
        if e.get("error"):
            lines.append(f"{e['index']:>3} {e['kind']:<8} {e['error']}")
            continue
        b = e["band_rpm"]
        felt = e.get("band_shuffle_pp_ms2")
        felt_text = f"{num(felt['p5'], '.2f')}-{num(felt['p95'], '.2f')}" if felt else "-"
        lines.append(f"{e['index']:>3} {e['kind']:<8} {num(b['p5']):>8} {num(b['p50']):>8} {num(b['p95']):>8} "
                     f"{num(e['nominal_fluctuation_rpm']):>8} {num(e['measured_fluctuation_rpm']):>9} "
                     f"{num(e['measured_percentile'], '.0f'):>5}% {num(e.get('analysis_fluctuation_rpm')):>10}"
                     f"   {felt_text:>12} {num(e.get('measured_shuffle_pp_ms2'), '.2f'):>8}")
    lines.append("pct: the measured (raw) ripple's percentile in the band; detrended: the same event's fluctuation in "
                 "the metrics table (detrended from the rigid-body trend, so it differs from the raw one); p-p: the "
                 "felt shuffle peak-to-peak of the body acceleration (docs/drivability.md)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from app.cli.report import (
        drivability_table,
        events_table,
        finding_lines,
        metrics_table,
        read_lines,
        summary_line,
        tracking_lines,
    )

    doc = analysis_doc(args)
    text = json.dumps(doc, indent=1)
    if args.out is not None:
        args.out.write_text(text, encoding="utf-8")
    if args.json:
        sys.stdout.write(text + "\n")
    else:
        for line in read_lines(doc["summary"].get("read")):
            print(line)
        print(summary_line(doc))
        print()
        print(events_table(doc))
        print()
        for note in doc.get("notes", []):
            print(f"note: {note}")
        for line in (*finding_lines(doc), *tracking_lines(doc)):
            print(line)
        print(metrics_table(doc))
        feel = drivability_table(doc)
        if feel:
            print()
            print(feel)
        if "gap_sensitivity" in doc:
            print()
            print(gap_sensitivity_table(doc["gap_sensitivity"]))
        if "tolerance" in doc:
            print()
            print(tolerance_table(doc["tolerance"]))
    return 0
