"""How often the identification's 90 % intervals cover the truth, per car, on the independent generator's sets.

``identify`` runs on drive A of every drive without an effect (``none`` and ``base``) of the given sets, told the
nominal car, as ``bench/identify_indep.py`` runs it. Each identified parameter's half-width is kept in its parts
(``Identification.interval_parts``: the statistics, the part of them the pins carry in, the log's model-form scale
and the misfit), so a saved run can be scored again under other model-form floors without identifying again
(``--load`` with ``--form``, or ``--no-pin-spread``): this is how ``app.identify.fit.MODEL_FORM`` was calibrated
(docs/identify.md, step 4). Calibrate on development sets only; a fresh set is scored once, with the floors fixed.

    .venv/bin/python bench/interval_coverage.py --sets idev2,ifinal4 --save /tmp/cov.jsonl
    .venv/bin/python bench/interval_coverage.py --load /tmp/cov.jsonl
    .venv/bin/python bench/interval_coverage.py --load /tmp/cov.jsonl --form mass=0.02,0.02 --form lash=0.02,0.02
    .venv/bin/python bench/interval_coverage.py --load /tmp/cov.jsonl --no-pin-spread
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.identify import IdentifyOptions, identify_logs  # noqa: E402
from app.identify.fit import MODEL_FORM, MOVE_FORM, model_form  # noqa: E402
from bench.diagnosis_indep import generate  # noqa: E402
from bench.identify_indep import OURS, PARAMS  # noqa: E402
from bench.indep.car import is_chain, vehicle_source  # noqa: E402
from bench.indep.cases import IDENTIFY_SETS  # noqa: E402
from bench.indep.record import DBC, MAP  # noqa: E402
from sim import load_vehicle  # noqa: E402

LEVEL = 0.9
MOVE_BINS = ((0.0, 0.15), (0.15, 0.5), (0.5, math.inf))  # the identified car's move from its file


def collect(sets: list[str]) -> list[dict[str, Any]]:
    """One row per identified drive: set, case, car, rate and per parameter value, truth and interval parts."""
    rows = []
    for which in sets:
        folder, todo = generate(which, False, 1, [])
        clean = [c for c in todo if c.kind in ("none", "base")]
        for i, case in enumerate(clean):
            t0 = time.process_time()
            try:
                res = identify_logs([folder / case.drive_a], load_vehicle(vehicle_source(case.car)),
                                    IdentifyOptions(dbc=DBC, signal_map=MAP, seed=case.seed))
            except Exception as exc:  # a benchmark reports a failure per case instead of stopping
                print(f"{which} [{i + 1}/{len(clean)}] {case.name}: {type(exc).__name__}: {exc}", flush=True)
                continue
            parts = res.identification.interval_parts
            row: dict[str, Any] = {"set": which, "case": case.name, "car": case.car, "rate_hz": case.rate_hz,
                                   "params": {}}
            for name, (truth_key, _) in PARAMS.items():
                q = OURS.get(name, name)
                p = res.params.get(q)
                if p is None or not p.identified or q not in parts:
                    continue
                row["params"][q] = {"value": p.value, "lo": p.lo, "hi": p.hi, "truth": case.truth[truth_key],
                                    "nominal": p.nominal, **parts[q]._asdict()}
            rows.append(row)
            print(f"{which} [{i + 1}/{len(clean)}] {case.name}: {len(row['params'])} parameters identified "
                  f"({time.process_time() - t0:.1f} s CPU)", flush=True)
    return rows


def move_of(row: dict[str, Any]) -> float:
    """The identified car's move from its file (``fit.move_from_file``): saved, or from the saved figures and the
    file's (rows saved before the move was part of the floor carry the file's figure as ``nominal``, or nothing: 0)."""
    for p in row["params"].values():
        if "move" in p:
            return float(p["move"])
    logs = [math.log(p["value"] / p["nominal"]) for p in row["params"].values() if p.get("nominal")]
    return math.sqrt(sum(x * x for x in logs))


def half_width(name: str, p: dict[str, Any], form: dict[str, tuple[float, float]], move: float = 0.0,
               per_move: float = MOVE_FORM, pins: bool = True) -> float:
    """90 % half-width (log scale) of saved parameter ``name`` under the model-form floors ``form`` and ``per_move``,
    on a drive whose identified car moved ``move`` from its file, as ``app.identify.fit.assemble`` computes it;
    ``pins=False``: without the part the pins' uncertainty carries into the statistics (``IntervalParts.pins``)."""
    stat = p["stat"] if pins else math.sqrt(max(p["stat"] ** 2 - p.get("pins", 0.0) ** 2, 0.0))
    return math.hypot(stat, math.log1p(model_form(name, p["scale"], form, move, per_move) * p["misfit"]))


def score(rows: list[dict[str, Any]], form: dict[str, tuple[float, float]], per_move: float = MOVE_FORM,
          pins: bool = True) -> None:
    """Coverage per parameter, for each car and for all drives, under the floors ``form`` and ``per_move`` (and with
    or without the pins' part of the statistics); and the paper car's by its identified car's move from the file."""
    print(f"{'parameter':10s} {'floor (level, slope)':22s} {'paper car':>16s} {'chain car':>16s} {'all':>16s}"
          f"   paper car moved {' | '.join(f'{lo:g}-{hi:g}' for lo, hi in MOVE_BINS)}")
    for q, (level, slope) in form.items():
        counts = {"paper": [0, 0], "chain": [0, 0]}
        by_move = [[0, 0] for _ in MOVE_BINS]
        for r in rows:
            p = r["params"].get(q)
            if p is None:
                continue
            c = counts["chain" if is_chain(r["car"]) else "paper"]
            move = move_of(r)
            hit = abs(math.log(p["value"] / p["truth"])) <= half_width(q, p, form, move, per_move, pins)
            c[0] += hit
            c[1] += 1
            if not is_chain(r["car"]):
                for k, (lo, hi) in enumerate(MOVE_BINS):
                    if lo <= move < hi:
                        by_move[k][0] += hit
                        by_move[k][1] += 1
        cells = [f"{h:3d}/{n:3d} {100 * h / n:5.1f} %" if n else f"{'-':>16s}" for h, n in counts.values()]
        h = counts["paper"][0] + counts["chain"][0]
        n = counts["paper"][1] + counts["chain"][1]
        cells.append(f"{h:3d}/{n:3d} {100 * h / n:5.1f} %" if n else f"{'-':>16s}")
        moved = " | ".join(f"{h}/{n} {100 * h / n:.0f} %" if n else "-" for h, n in by_move)
        print(f"{q:10s} {f'{level:g}, {slope:g}':22s} " + " ".join(f"{c:>16s}" for c in cells) + f"   {moved}")


def check_parts(rows: list[dict[str, Any]]) -> int:
    """Intervals whose saved width is not what their parts give under the code's floors (0 on a run of this code;
    rows saved before the move was part of the floor were made under other floors and are not checked)."""
    bad = 0
    for r in rows:
        if not any("move" in p for p in r["params"].values()):
            continue
        for q, p in r["params"].items():
            half = math.log(p["hi"] / p["value"])
            bad += abs(half - half_width(q, p, MODEL_FORM, move_of(r))) > 1e-9 * max(1.0, half)
    return bad


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", default="idev2", help="comma-separated identification sets (development sets only)")
    ap.add_argument("--save", type=Path, help="write the collected rows (JSON lines)")
    ap.add_argument("--load", type=Path, help="score saved rows instead of identifying")
    ap.add_argument("--form", action="append", default=[], metavar="NAME=LEVEL,SLOPE",
                    help="score under this model-form floor instead of the code's (repeatable)")
    ap.add_argument("--per-move", type=float, default=MOVE_FORM,
                    help="score with this floor per unit of the identified car's move from its file "
                         f"(the code's: {MOVE_FORM:g})")
    ap.add_argument("--no-pin-spread", action="store_true",
                    help="score without the part of the statistics the pins' uncertainty carries in (rows saved "
                         "before it was part of the intervals have none)")
    args = ap.parse_args()
    form = dict(MODEL_FORM)
    for item in args.form:
        name, _, nums = item.partition("=")
        if name not in form:
            ap.error(f"--form: unknown parameter {name!r}; known: {', '.join(form)}")
        level, slope = (float(x) for x in nums.split(","))
        form[name] = (level, slope)
    if args.load:
        rows = [json.loads(line) for line in args.load.read_text(encoding="utf-8").splitlines() if line.strip()]
    else:
        sets = args.sets.split(",")
        unknown = [s for s in sets if s not in IDENTIFY_SETS]
        if unknown:
            ap.error(f"unknown sets {unknown}; known: {', '.join(IDENTIFY_SETS)}")
        rows = collect(sets)
        if args.save:
            args.save.write_text("".join(json.dumps(r) + "\n" for r in rows), encoding="utf-8")
    given = bool(args.form) or args.per_move != MOVE_FORM or args.no_pin_spread
    print(f"\n{len(rows)} drives without an effect; 90 % intervals covering the truth "
          f"({'given' if given else 'the code'} floors, {args.per_move:g} per unit of move)")
    if not given:
        earlier = sum(not any("move" in p for p in r["params"].values()) for r in rows)
        print(f"intervals not reproduced from their parts: {check_parts(rows)}"
              + (f" ({earlier} drives saved under earlier floors not checked)" if earlier else ""))
    if args.no_pin_spread:
        print("without the pins' spread in the statistics")
    score(rows, form, args.per_move, not args.no_pin_spread)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
