"""CPU per diagnosis: the fit's simulator passes on the reference path against the fast path, same run.

Drives come from the independent generator (``bench/indep``): 60 s paper-car drives logged at 1 kHz
with a library effect on top of a wrong data sheet (the slow case: a large sim-to-real gap makes
every candidate fit run its whole pass budget), cached as BLF under ``bench/out/indep/cpu/``.
Each drive is diagnosed twice in this process: the reference path (what a diagnosis did before:
OpenBLAS at its own thread count, the full ``sim.simulate`` output per run, the numpy offset
profile, no residual memo, a Jacobian's columns one after the other -- ``blas_threads.ENABLED``,
``forward.LEAN_SIM``, ``calibrate.PARALLEL_POINTS`` off, ``calibrate.MEMO_POINTS`` 0) and the default
path. Printed per drive: CPU seconds (``time.process_time``: every thread of the process, BLAS
workers included) and wall seconds of each, their ratio, whether the decision is the same, and the
largest relative difference over every fit's nuisance and effect values and chi2.

    .venv/bin/python bench/diagnosis_cpu.py            # the 1 kHz drives
    .venv/bin/python bench/diagnosis_cpu.py --profile  # and a cProfile of the fast path (top 20)
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.analysis import blas_threads  # noqa: E402
from app.analysis.diagnosis import (  # noqa: E402
    DiagnosisOptions,
    DiagnosisResult,
    calibrate,
    diagnose_signals,
    forward,
)
from bench.indep.car import vehicle_source  # noqa: E402
from bench.indep.cases import EFFECT_DRAWS, Case, build, read_manifest, write_manifest  # noqa: E402
from bench.indep.record import DBC, MAP  # noqa: E402
from sim import load_vehicle  # noqa: E402
from tests.support.truthlog import read_log  # noqa: E402

OUT = REPO / "bench" / "out" / "indep" / "cpu"


def plan() -> list[Case]:
    """1 kHz paper-car drives: drag and tyre slip each on a data sheet with a stiffness and a lash off."""
    out = []
    for k, eff in enumerate(("drag", "tyre_slip")):
        seed = 910_000 + k
        r = np.random.default_rng(seed)
        out.append(Case(f"cpu_{eff}_{seed}", "base_effect", seed, {eff: EFFECT_DRAWS[eff](r)}, [eff], 60.0,
                        base={"k_scale": 0.75, "gap_scale": 1.3}, rate_hz=1000.0))
    return out


def cases() -> list[Case]:
    manifest = OUT / "manifest.json"
    done = {c.name: c for c in read_manifest(manifest)} if manifest.exists() else {}
    todo = plan()
    missing = [c for c in todo if c.name not in done or not (OUT / done[c.name].drive_a).exists()]
    if missing:
        OUT.mkdir(parents=True, exist_ok=True)
        for c in missing:
            t0 = time.time()
            done[c.name] = build(c, OUT)
            print(f"generated {c.name} ({time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
        write_manifest(manifest, list(done.values()))
    return [done[c.name] for c in todo]


@dataclass
class Run:
    cpu_s: float
    wall_s: float
    result: DiagnosisResult


def run(case: Case, fast: bool, profile: bool = False, broyden: int = 0) -> Run:
    vehicle = load_vehicle(vehicle_source(case.car))
    memo = calibrate.MEMO_POINTS
    signals = read_log(OUT / case.drive_a, DBC, MAP)
    blas_threads.ENABLED = fast
    calibrate.MEMO_POINTS = calibrate.MEMO_POINTS if fast else 0
    forward.LEAN_SIM = fast
    calibrate.PARALLEL_POINTS = fast
    calibrate.BROYDEN_EVERY = broyden if fast else 0
    prof = cProfile.Profile() if profile else None
    t0, w0 = time.process_time(), time.perf_counter()
    try:
        if prof is not None:
            prof.enable()
        res = diagnose_signals(signals, vehicle, DiagnosisOptions(seed=case.seed))
        if prof is not None:
            prof.disable()
    finally:
        blas_threads.ENABLED = True
        calibrate.MEMO_POINTS = memo
        forward.LEAN_SIM = True
        calibrate.PARALLEL_POINTS = True
        calibrate.BROYDEN_EVERY = 0
    cpu, wall = time.process_time() - t0, time.perf_counter() - w0
    if prof is not None:
        pstats.Stats(prof).sort_stats("tottime").print_stats(20)
    return Run(cpu, wall, res)


def _fitted(res: DiagnosisResult) -> dict[str, float]:
    """Every candidate fit's nuisance and effect values, and its chi2, flattened by name."""
    out: dict[str, float] = {}
    fits: list[Any] = []
    for attr in ("baseline", "candidates", "fits"):
        v = getattr(res, attr, None)
        if v is None:
            continue
        fits.extend(v.values() if isinstance(v, dict) else (v if isinstance(v, (list, tuple)) else [v]))
    for f in fits:
        f = getattr(f, "fit", f)
        if not hasattr(f, "nuisance"):
            continue
        key = "+".join(f.effects) or "baseline"
        for n, x in f.nuisance.to_dict().items():
            out[f"{key}:{n}"] = float(x)
        for e, vals in f.values.items():
            for n, x in vals.items():
                out[f"{key}:{e}.{n}"] = float(x)
        out[f"{key}:chi2"] = float(f.chi2)
    return out


def max_rel(a: dict[str, float], b: dict[str, float]) -> float:
    keys = set(a) | set(b)
    if set(a) != set(b):
        return float("inf")
    return max((abs(a[k] - b[k]) / max(abs(a[k]), abs(b[k]), 1e-12) for k in keys), default=0.0)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--profile", action="store_true", help="cProfile of the fast path")
    ap.add_argument("--case", action="append", default=[], help="only this case (repeatable)")
    ap.add_argument("--broyden", type=int, default=0, metavar="N",
                    help="fast path with calibrate.BROYDEN_EVERY = N (a finite-difference Jacobian every N "
                         "trust-region steps, rank-one updates between; other numbers, so compare the decision)")
    args = ap.parse_args()
    todo = [c for c in cases() if not args.case or c.name in args.case]
    print(f"diagnosis CPU, reference path vs fast path: {len(todo)} drives, 60 s at 1 kHz, paper car"
          + (f"; fast path with a finite-difference Jacobian every {args.broyden} steps" if args.broyden > 1 else ""))
    total = [0.0, 0.0]
    for c in todo:
        ref = run(c, fast=False)
        new = run(c, fast=True, profile=args.profile, broyden=args.broyden)
        total[0] += ref.cpu_s
        total[1] += new.cpu_s
        dr, dn = ref.result.decision, new.result.decision
        same = dr.status == dn.status and tuple(dr.top) == tuple(dn.top)
        fr, fn = _fitted(ref.result), _fitted(new.result)
        print(f"{c.name:28s} {len(new.result.events):3d} events  reference {ref.cpu_s:6.1f} s CPU  "
              f"fast {new.cpu_s:6.1f} s CPU  ratio {ref.cpu_s / new.cpu_s:5.2f}  "
              f"wall {ref.wall_s:5.1f} -> {new.wall_s:5.1f} s  "
              f"decision {dn.status} {'+'.join(dn.top) or '-'}  same decision: {'yes' if same else 'no'}  "
              f"max rel diff of {len(fn)} fitted values {max_rel(fr, fn):.1e}", flush=True)
    if todo:
        print(f"total: reference {total[0]:.1f} s CPU, fast {total[1]:.1f} s CPU, ratio {total[0] / total[1]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
