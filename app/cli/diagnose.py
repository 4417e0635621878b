"""``lashscope diagnose LOG --vehicle V [--validate OTHER_LOG] [--json]``: where, why and how far.

Decodes the log, finds the tip-in/tip-out events, freezes a calibration/held-out split, fits
every candidate effect jointly with the nuisance parameters on calibration events, scores them on
held-out events and prints the decision with its evidence. Progress goes to stderr.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from app.cli.report import identified_param, read_lines
from app.cli.vehicle_args import add_log_and_vehicle, event_params, vehicle_inputs
from app.progress import eta_text


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "diagnose", help="diagnose the sim-to-real gap: where it lies, which effect explains it",
        description="Fit candidate unmodelled effects on calibration events of LOG, score them on held-out events "
        "and decide which one explains the gap between simulated and measured motor speed.")
    add_log_and_vehicle(p)
    p.add_argument("--validate", type=Path, default=None, metavar="OTHER_LOG",
                   help="another drive: report the shrink of the diagnosed effect there")
    # the ids are not listed here: importing the simulator (numba) would slow every command's start-up
    p.add_argument("--candidates", default=None,
                   help="comma-separated candidate effects (default: all; ids in docs/diagnosis.md, e.g. "
                        "backlash,torque_lag,drag)")
    p.add_argument("--seed", type=int, default=0, help="seed of the calibration/held-out split")
    p.add_argument("--model", choices=["multibody", "two_inertia"], default="multibody")
    p.add_argument("--model-form-tolerance", type=float, default=0.0, metavar="F",
                   help="residual under F x the local predicted oscillation is no evidence of a gap (0..1; "
                        "default 0: sensor noise alone; see docs/diagnosis.md)")
    p.add_argument("--all-events", action="store_true",
                   help="diagnose every event in one stage (default: the sequential design, which stops adding "
                        "events once two stratified stages of 24, 48, ... events per side agree; see "
                        "docs/diagnosis.md)")
    p.add_argument("--plots", type=Path, default=None, metavar="DIR", help="write overlay and residual PNGs here")
    p.add_argument("--out", type=Path, default=None, help="also write the JSON report to this file")
    p.add_argument("--json", action="store_true", help="print the JSON report instead of the summary")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=run)


def _progress(quiet: bool) -> Any:
    start = time.perf_counter()

    def say(fraction: float, message: str) -> None:
        if not quiet:
            elapsed = time.perf_counter() - start
            print(f"[{100 * fraction:3.0f} % {elapsed:5.1f} s{eta_text(fraction, elapsed)}] {message}",
                  file=sys.stderr, flush=True)

    return say


def _pct(iv: dict[str, float] | None) -> str:
    """``value % [lo, hi]``; a share above 100 % is starred (see :data:`OVER_FULL_NOTE`)."""
    if not iv:
        return "-"
    star = "*" if iv["value"] > 1.0 else ""
    return f"{100 * iv['value']:.0f} %{star} [{100 * iv['lo']:.0f}, {100 * iv['hi']:.0f}]"


OVER_FULL_NOTE = ("* above 100 %: the fit removed more than the residual above the noise floor (part of the noise "
                  "as well); explained share = residual removed / residual above the noise floor, held-out shrink = "
                  "residual energy removed / residual energy")


def _ratio(iv: dict[str, float] | float | None) -> str:
    value = iv.get("value") if isinstance(iv, dict) else iv
    return "-" if value is None else f"{value:.2f}x"


def _residual_lines(d: dict[str, Any]) -> list[str]:
    """The held-out residual in rpm beside its ratio to the noise floor, and an event that carries most of it."""
    before = d.get("residual_rms_rpm_before")
    if before is None:
        return []
    after = d.get("residual_rms_rpm_after")
    line = (f"held-out residual: {before:.2f} rpm RMS ({_ratio(d.get('residual_to_noise_before'))} the noise floor)"
            + (f", {after:.2f} rpm after {' + '.join(d['top'])} ({_ratio(d.get('residual_to_noise_after'))})"
               if after is not None and d.get("top") else ""))
    one = d.get("dominant_event")
    if not one:
        return [line]
    return [line, f"  event {one['index']} carries {100 * one['share']:.0f} % of the residual above the noise floor; "
                  f"without it {one['residual_to_noise_without']:.2f}x"]


def summary(doc: dict[str, Any]) -> str:
    d = doc["decision"]
    lines = read_lines(doc.get("read"))
    lines += read_lines((doc.get("validation") or {}).get("read"), "validation log: ")
    lines += [f"WARNING [{f['code']}]: {f['message']}" for f in doc.get("findings") or []]
    lines += [f"decision: {d['status'].upper()}" + (f"  top: {' + '.join(d['top'])}" if d["top"] else "")
             + (f"  confusable: {' / '.join(d['confusable'])}" if d.get("confusable") else ""),
             f"  {d['reason']}"]
    sp = doc["split"]
    lines.append(f"split: seed {sp['seed']}, {len(sp['calibration'])} calibration / {len(sp['heldout'])} held-out "
                 f"events, sha256 {sp['sha256'][:16]}")
    nf = doc["noise_floor"]
    lines.append(f"noise floor: {nf['sigma_rpm']:.2f} rpm white, {nf['quant_step_rpm']:g} rpm steps, "
                 f"{1e3 * nf['jitter_s']:.2f} ms jitter, {1e3 * nf['period_s']:.1f} ms period")
    lines += _residual_lines(d)
    if doc["baseline"]:
        nu = doc["baseline"]["nuisance"]
        lines.append(f"baseline nuisance: offset {1e3 * nu['offset_s']:+.1f} ms, gain {nu['gain']:.3f}, "
                     f"road load {nu['road_load_grade_pct']:+.2f} % grade"
                     + (f"  AT BOUND: {', '.join(doc['baseline']['at_bound'])}" if doc["baseline"]["at_bound"] else ""))
    if doc["candidates"]:
        lines += ["", f"{'candidate':34s} {'held-out shrink':>22s} {'explained share':>22s} {'improved':>9s}  params"]
        for c in doc["candidates"] + doc["pairs"]:
            h = c["heldout"]
            params = "; ".join(f"{k}={v:.4g}" if eff in c["effects"] else f"{eff}.{k}={v:.4g}"
                               for eff, vals in c["fit"]["params"].items() for k, v in vals.items())
            lines.append(f"{c['id']:34s} {_pct(h['shrink']):>22s} {_pct(h['explained_share']):>22s} "
                         f"{100 * h['improved_fraction']:8.0f}%  {params}")
        if any("%*" in line for line in lines):
            lines.append(OVER_FULL_NOTE)
    ident = doc.get("identification")
    if ident and "params" not in ident:  # too few events to identify: say why instead of a table
        lines += ["", f"identification of the base parameters skipped: {ident.get('skipped', 'no result')}"]
    elif ident:
        ho = ident.get("heldout") or {}
        lines += ["", "identification of the base parameters (calibration events; held-out shrink "
                      f"{_pct(ho.get('shrink'))}):"]
        lines += [f"  {p['label']:44s} {identified_param(p)}" for p in ident["params"].values()]
    loc = doc.get("localisation")
    if loc:
        lines += ["", "where (held-out, baseline): phase, share of the residual energy, residual RMS / noise floor"]
        for p in loc["phases"]:
            r = p["residual_to_noise"]
            lines.append(f"  {p['phase']:13s} {100 * (p['energy_share'] or 0):5.1f} %  "
                         f"{'-' if r is None else f'{r:.2f}x'}")
        lines.append("  band, share of the residual energy, coherence with torque (0..1)")
        for b in loc["bands"]:
            coh = b["coherence"]
            shown = "-" if coh is None else f"{coh:.2f}"
            lines.append(f"  {b['band']:8s} {100 * (b['energy_share'] or 0):5.1f} %  {shown}")
        lines += [f"  note: {n}" for n in loc["notes"]]
    rem = d.get("remainder")
    if rem:
        lines.append(f"remainder: {rem['status']}, {rem['ratio_to_noise']:.2f}x the noise floor"
                     + (f" in {', '.join(rem['where'])}; not explained by any candidate"
                        if rem["status"] == "structured" else ""))
    val = doc.get("validation")
    if val and "skipped" in val:
        lines += ["", f"validation on another drive skipped: {val['skipped']}"]
    elif val:
        lines += ["", f"validation on another drive ({val['events']} events): held-out shrink "
                      f"{_pct(val['shrink'])}, explained share {_pct(val['explained_share'])}"]
        if "%*" in lines[-1] and OVER_FULL_NOTE not in lines:
            lines.append(OVER_FULL_NOTE)
    lines.append(f"\ndiagnosis took {doc['elapsed_s']:.1f} s (wall time)")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from app.analysis.diagnosis import DiagnosisOptions, diagnose_checked, report_dict, validate_on
    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
    from app.analysis.logchecks import Limits, check_log
    from app.errors import InputError
    from app.pipeline import decode_log
    from sim.effects import EFFECTS

    given = ",".join(EFFECTS) if args.candidates is None else args.candidates
    candidates = tuple(c.strip() for c in given.split(",") if c.strip())
    if not candidates:
        raise InputError("--candidates is empty")
    thresholds = event_params(args, DIAGNOSIS_EVENTS)  # refused before anything is decoded
    inputs = vehicle_inputs(args)
    vehicle, dbc, smap = inputs.vehicle, inputs.database, inputs.signal_map
    options = DiagnosisOptions(candidates=candidates, seed=args.seed, model=args.model,
                               model_form_rel=args.model_form_tolerance, sequential=not args.all_events)
    say = _progress(args.quiet)
    say(0.0, f"decoding {args.log}")
    signals, ingest = decode_log(args.log, dbc, smap)
    result, checked = diagnose_checked(signals, vehicle, options, say, thresholds)
    validation = None
    if args.validate is not None and (result.decision.top or result.decision.details.get("base_parameters")):
        say(0.0, f"decoding {args.validate}")
        other, other_ingest = decode_log(args.validate, dbc, smap)
        other_checked = check_log(other, Limits.for_vehicle(vehicle))
        validation = validate_on(result, other_checked.signals, vehicle, progress=say,
                                 event_params=thresholds).to_dict()
        validation["findings"] = [f.to_dict() for f in other_checked.findings]
        validation["read"] = other_ingest["read"]
    elif args.validate is not None:
        validation = {"skipped": f"decision {result.decision.status}: no effect to validate"}
    doc = report_dict(result, validation, checked.findings)
    doc["read"] = ingest["read"]  # damaged or truncated input, stated with the answer
    if args.plots is not None and result.baseline is not None:
        from app.diagnosis_plots import event_overlay_png, residual_chart_png

        doc["plots"] = [str(event_overlay_png(result, args.plots / "diagnosis_events.png")),
                        str(residual_chart_png(result, args.plots / "diagnosis_residual.png"))]
    text = json.dumps(doc, indent=1, allow_nan=False, default=str)
    if args.out is not None:
        args.out.write_text(text, encoding="utf-8")
    sys.stdout.write(text + "\n" if args.json else summary(doc) + "\n")
    return 0
