"""Fit the paper's unpublished inputs to all of its figures at once and write the fitted preset.

Run: ``.venv/bin/python bench/paper_fit.py [--seed 0] [--popsize 8] [--maxiter 30] [--out PATH]``
(single process, a few minutes of CPU). Without ``--out`` it writes
``sim/presets/paper_fitted.toml``, the only stored result of the fit; the same seed and budget
give the same file. Prints the starting rows (the ``paper`` preset with its own ramp), the fit's
progress, the rows at the fit, the clearance-unit comparison, and S1..S5 with the housing and
the half-shaft segmentation switched (does flexibility lift S4 and S5 above S3?).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from sim import load_vehicle
from sim.paper import format_table, paper_cases, reproduce, sensitivities, sensitivity_table
from sim.paper_fit import fit, fitted_toml

OUT = Path(__file__).resolve().parent.parent / "sim" / "presets" / "paper_fitted.toml"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--popsize", type=int, default=8)
    ap.add_argument("--maxiter", type=int, default=30)
    ap.add_argument("--polish", type=int, default=300, help="Powell polish evaluations")
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args()
    base = load_vehicle("paper")
    rows, _ = reproduce(base)
    print("[start] paper preset, its -50 -> +150 N m / 0.135 s ramp")
    print(format_table(rows), flush=True)
    t0 = time.process_time()
    res = fit(base, seed=a.seed, popsize=a.popsize, maxiter=a.maxiter, polish_evals=a.polish,
              progress=lambda n, c: print(f"  {n:5d} evaluations, best cost {c:.4g}", flush=True))
    cpu = time.process_time() - t0
    print(f"[fit] {res.evaluations} evaluations, {cpu:.0f} s CPU, cost {res.cost:.4g}")
    for p, x in zip(res.params, res.x, strict=True):
        print(f"  {p.field:<26} {x:12.6g}   [{p.lo:.4g}, {p.hi:.4g}]")
    rows, cases = reproduce(res.vehicle, res.tip_in)
    table = format_table(rows)
    print(table)
    print(sensitivity_table(res.vehicle, cases))
    print("[flex] S1..S5 per arc-minute (S5 = 100) on the fitted vehicle: do the housing and the half-shaft's")
    print("       flexibility lift S4, S5 above S3?")
    for change in ({}, {"housing.enabled": False}, {"halfshaft.segments": 1}, {"halfshaft.segments": 6},
                   {"housing.enabled": False, "halfshaft.segments": 1}):
        v = res.vehicle.with_changes(change)
        s = sensitivities(v, paper_cases(v, res.tip_in, twin=False), per="arcmin", quantity="fluctuation")
        print(f"  {change or 'as fitted'!s:<52} " + " : ".join(f"{x:.1f}" for x in s))
    a.out.write_text(fitted_toml(res, table, base), encoding="utf-8")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
