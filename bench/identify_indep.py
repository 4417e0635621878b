"""Vehicle identification benchmark on drives made by the independent generator (``bench/indep``).

The generator's ``idev`` and ``ifinal`` sets (``bench.indep.cases.plan_identify``) drive cars whose data
sheet is wrong: half-shaft stiffness, shaft and mesh damping, body mass and clearances off (``base``),
the same within 20 % plus one library effect (``base_effect``), or nothing off (``none``); the paper
car logged at 100 Hz or 1 kHz and the chain_drive car, heavily damped, logged at 20-50 Hz in bursts.
Each case's truths are the generator's own (``Case.truth``). For every case ``identify`` runs on
drive A with drive B withheld, told the nominal car (``bench.indep.car.vehicle_source``), and the
diagnosis runs on drive A as ``bench/diagnosis_indep.py`` runs it. ``idev2`` and ``ifinal2`` drive the low-mode
chain car of ``bench/indep/chain_low.toml`` instead (a 5.5 Hz first mode, as the formula-student logs show).

Printed: one line per case, then the targets as PASS/FAIL with their figures and the CPU seconds
per identification and per diagnosis. Without ``app.identify`` the drives are still made and the
diagnosis still scored; the identification targets are reported unavailable.

    .venv/bin/python bench/identify_indep.py --set idev --quick      # 9 cases, 40 s drives
    .venv/bin/python bench/identify_indep.py --set idev --jobs 2     # 35 cases, 60 s drives
    .venv/bin/python bench/identify_indep.py --set idev --case chain_none_210033 --generate-only
    .venv/bin/python bench/identify_indep.py --set ifinal            # scored once, with the rule fixed
    .venv/bin/python bench/identify_indep.py --set idev2 --jobs 2    # the low-mode chain car (chain_low.toml)
    .venv/bin/python bench/identify_indep.py --set ifinal2           # its fresh set, scored once
    .venv/bin/python bench/identify_indep.py --set ifinal11 --jobs 2 --no-separable  # without the separable step
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from bench.diagnosis_indep import Result, Serial, diagnose, generate  # noqa: E402
from bench.diagnosis_report import CONFIDENT, pct  # noqa: E402
from bench.indep.car import is_chain, vehicle_source  # noqa: E402
from bench.indep.cases import IDENTIFY_SETS, Case  # noqa: E402
from bench.indep.record import DBC, MAP  # noqa: E402
from bench.separable import SEPARABLE_SIGMA, separable  # noqa: E402
from sim import load_vehicle  # noqa: E402

try:
    from app.identify import IdentifyOptions, identify_logs
    UNAVAILABLE = ""
except ImportError as exc:  # identification not in this checkout: the drives and the diagnosis are still scored
    IdentifyOptions = identify_logs = None  # type: ignore[assignment,misc]
    UNAVAILABLE = str(exc)

# identified parameter -> (truth key in Case.truth, relative tolerance of the target)
PARAMS = {"stiffness": ("stiffness", 0.10), "damping_ratio": ("zeta", 0.20), "mass": ("mass", 0.05),
          "lash": ("lash_mrad", 0.15)}
OURS = {"damping_ratio": "damping"}  # the generator's parameter name -> lashscope's (its figure is the damping ratio)
COVERAGE = (0.80, 0.97)  # 90 % intervals must cover the truth in this fraction of drives
FREQ_TOL = 0.05
NRMSE_MAX = 0.2
CPU_IDENTIFY_S, CPU_DIAGNOSE_S = 30.0, 60.0  # per 60 s log


@dataclass
class Identified:
    """What ``identify`` said about one case (plain values: it crosses process boundaries)."""

    params: dict[str, tuple[float, float, float]] = field(default_factory=dict)  # name -> (value, lo, hi)
    freq_hz: float = float("nan")
    zeta: float = float("nan")
    named: tuple[str, ...] = ()
    nrmse_before: float = float("nan")
    nrmse_after: float = float("nan")
    cpu_s: float = float("nan")
    error: str = ""


@dataclass
class Outcome:
    case: Case
    ident: Identified | None  # None: identification unavailable
    diag: Result


def identify(case: Case, folder: Path) -> Identified | None:
    """``identify`` on drive A with drive B withheld, told the case's nominal car."""
    if identify_logs is None:
        return None
    vehicle = load_vehicle(vehicle_source(case.car))
    opts = IdentifyOptions(dbc=DBC, signal_map=MAP, seed=case.seed)
    t0 = time.process_time()
    try:
        res = identify_logs([folder / case.drive_a], vehicle, opts, validate=[folder / case.drive_b])
    except Exception as exc:  # a benchmark reports a failure per case instead of stopping
        return Identified(error=f"{type(exc).__name__}: {exc}")
    cpu = time.process_time() - t0
    params = {k: (float(res.params[OURS.get(k, k)].value), float(res.params[OURS.get(k, k)].lo),
                  float(res.params[OURS.get(k, k)].hi)) for k in PARAMS if OURS.get(k, k) in res.params}
    theirs = {v: k for k, v in OURS.items()}
    modal = res.modal
    return Identified(params, float(modal.freq_hz) if modal else float("nan"),
                      float(modal.zeta) if modal else float("nan"), tuple(theirs.get(n, n) for n in res.named),
                      _num(res.validation.get("nrmse_before")), _num(res.validation.get("nrmse_after")), cpu)


def _num(x: float | None) -> float:
    return float("nan") if x is None else float(x)


def run(case: Case, folder: Path) -> Outcome:
    return Outcome(case, identify(case, folder), diagnose(case, folder))


def _err(idn: Identified, name: str, case: Case) -> float:
    """Relative error of an identified parameter against the truth (nan when not identified)."""
    if name not in idn.params:
        return float("nan")
    return idn.params[name][0] / case.truth[PARAMS[name][0]] - 1


def _covers(idn: Identified, name: str, case: Case) -> bool:
    if name not in idn.params:
        return False
    _, lo, hi = idn.params[name]
    return lo <= case.truth[PARAMS[name][0]] <= hi


def _diag_label(r: Result) -> str:
    if r.status in CONFIDENT:
        return f"{r.status} {'+'.join(r.top)}"
    if r.base_named:
        return f"{r.status} ({','.join(r.base_named)})"
    return r.status


def line(o: Outcome) -> str:
    c, idn = o.case, o.ident
    head = f"{c.name[:44]:44s} {c.car[:5]:5s} {c.rate_hz:6.1f} Hz"
    if idn is None:
        body = "identify unavailable"
    elif idn.error:
        body = f"identify error: {idn.error}"
    else:
        errs = " ".join(f"{k[:5]} {100 * _err(idn, k, c):+6.1f}%" for k in PARAMS)
        f_err = idn.freq_hz / c.truth["freq_hz"] - 1
        body = (f"{errs}  f {100 * f_err:+5.1f}%  named {','.join(idn.named) or '-':22s} "
                f"B nrmse {idn.nrmse_before:.3f}->{idn.nrmse_after:.3f}  {idn.cpu_s:5.1f} s")
    return f"{head}  {body}  | diagnosis {_diag_label(o.diag)} {o.diag.cpu_s:5.1f} s" + (
        f"  {o.diag.error}" if o.diag.error else "")


def check(name: str, ok: bool, value: str) -> None:
    print(f"  [{'PASS' if ok else 'FAIL'}] {name}: {value}")


def share(name: str, hit: int, n: int, lo: float, hi: float = 1.0, extra: str = "") -> None:
    """A target on the fraction ``hit / n`` (PASS when within ``[lo, hi]``); no drives of the kind: n/a."""
    if n == 0:
        print(f"  [n/a] {name}: no drives of this kind")
        return
    check(name, lo <= hit / n <= hi, pct(hit, n) + extra)


def identification_targets(out: list[Outcome]) -> None:
    """Parameter accuracy and coverage, modal frequency, naming and withheld-drive tracking."""
    idd = [o for o in out if o.ident is not None and not o.ident.error]
    failed = [o for o in out if o.ident is not None and o.ident.error]
    if failed:
        print(f"  [info] identification failed on {len(failed)} drives: "
              + ", ".join(o.case.name for o in failed[:5]))
    clean = [o for o in idd if o.case.kind in ("none", "base")]  # the truth is a car lashscope's family holds
    for name, (_, tol) in PARAMS.items():
        errs = [abs(_err(o.ident, name, o.case)) for o in clean if o.ident is not None]
        ok = sum(e <= tol for e in errs)
        share(f"{name} within {100 * tol:.0f} % of the truth in >= 90 % (none and base drives)", ok, len(errs), 0.9,
              extra=f"; median |error| {100 * np.nanmedian(errs):.1f} %" if errs else "")
        # an interval exists only where the parameter was identified (a parameter the log cannot show -- a mode above
        # what the sampling resolves, a lash crossed within a sample -- is held at the file's value, and said so)
        with_ci = [o for o in clean if o.ident is not None and name in o.ident.params
                   and np.isfinite(o.ident.params[name][1])]
        cov = sum(_covers(o.ident, name, o.case) for o in with_ci if o.ident is not None)
        share(f"{name}: 90 % interval covers the truth in 80-97 % (drives where it was identified: {len(with_ci)} of "
              f"{len(clean)})", cov, len(with_ci), *COVERAGE)
    mixed = [o for o in idd if o.case.kind == "base_effect"]
    if mixed:
        print("  [info] base parameters off <= 20 % with an effect: within tolerance "
              + ", ".join(f"{k} {pct(sum(abs(_err(o.ident, k, o.case)) <= t for o in mixed if o.ident), len(mixed))}"
                          for k, (_, t) in PARAMS.items()))
    for label, group in (("50 Hz bursty (chain car)", [o for o in idd if is_chain(o.case.car)
                                                        and o.case.rate_hz == 50.0]),
                         ("1 kHz (paper car)", [o for o in idd if o.case.rate_hz == 1000.0])):
        errs = [abs(o.ident.freq_hz / o.case.truth["freq_hz"] - 1) for o in group if o.ident]
        ok = sum(e <= FREQ_TOL for e in errs)
        share(f"modal frequency within 5 % at {label}", ok, len(errs), 1.0,
              extra=f"; max |error| {100 * max(errs):.1f} %" if errs else "")
    slow = [o for o in idd if is_chain(o.case.car) and o.case.rate_hz < 50.0]
    if slow:
        errs = [abs(o.ident.freq_hz / o.case.truth["freq_hz"] - 1) for o in slow if o.ident]
        print(f"  [info] chain car at 20-33 Hz (the chain_drive car's ~16 Hz mode is at or above Nyquist there): "
              f"modal frequency within 5 % "
              f"{pct(sum(e <= FREQ_TOL for e in errs), len(errs))}")
    base = [o for o in idd if o.case.kind == "base"]
    all_named = [o for o in base if o.ident and set(o.case.moved()) <= set(o.ident.named)]
    share(">= 90 % parameter-only drives with every moved parameter named", len(all_named), len(base), 0.9)
    recall = []
    for name in PARAMS:
        moved = [o for o in base if name in o.case.moved()]
        hit = sum(bool(o.ident and name in o.ident.named) for o in moved)
        recall.append(f"{name} {pct(hit, len(moved))}")
    print("  [info] recall per parameter: " + "; ".join(recall))
    extra = [o for o in base if o.ident and set(o.ident.named) - set(o.case.moved())]
    print(f"  [info] parameter-only drives naming a parameter that was not moved: {pct(len(extra), len(base))}")
    tracked = [o for o in idd if o.ident and o.ident.nrmse_after <= NRMSE_MAX]
    share(f"withheld drive NRMSE <= {NRMSE_MAX} after identification in >= 90 %", len(tracked), len(idd), 0.9,
          extra=(f"; median before {np.nanmedian([o.ident.nrmse_before for o in idd if o.ident]):.3f}, after "
             f"{np.nanmedian([o.ident.nrmse_after for o in idd if o.ident]):.3f}" if idd else ""))
    cpu = [o.ident.cpu_s for o in idd if o.ident]
    per_min = [o.ident.cpu_s * 60.0 / o.case.duration_s for o in idd if o.ident]
    if cpu:
        print(f"  CPU seconds per identify: median {np.median(cpu):.1f}, max {np.max(cpu):.1f}")
        check(f"identify <= {CPU_IDENTIFY_S:.0f} s CPU per 60 s log", max(per_min) <= CPU_IDENTIFY_S,
              f"max {max(per_min):.1f} s per 60 s of log")


def lash_for_backlash(o: Outcome) -> bool:
    """A backlash drive answered "the total lash is off the file": the same physical finding (the library's
    ``backlash`` effect is lash sizes off the nominal; identification reports their total as a base parameter)."""
    return tuple(o.case.expected) == ("backlash",) and o.diag.status == "base_parameters" \
        and "lash" in o.diag.base_named


def diagnosis_targets(out: list[Outcome], apart: dict[str, float] | None = None) -> None:
    """Attribution on parameter-only, effect and no-effect drives, and the diagnosis' CPU time."""
    base = [o for o in out if o.case.kind == "base"]
    effect_named = [o for o in base if o.diag.status in CONFIDENT]
    share("parameter-only drives: an unmodelled effect named in 0", len(effect_named), len(base), 0.0, 0.0)
    said_base = [o for o in base if o.diag.status == "base_parameters"]
    print(f"  [info] parameter-only drives the diagnosis calls base_parameters: {pct(len(said_base), len(base))}")
    mixed = [o for o in out if o.case.kind == "base_effect"]
    right = [o for o in mixed if (o.diag.status in CONFIDENT and o.diag.top == tuple(o.case.expected))
             or lash_for_backlash(o)]
    wrong = [o for o in mixed if o.diag.status in CONFIDENT and not set(o.diag.top) <= set(o.case.expected)]
    share(">= 85 % effects named correctly with base parameters off <= 20 %", len(right), len(mixed), 0.85)
    share("0 wrong-confident with base parameters off", len(wrong), len(mixed), 0.0, 0.0)
    if mixed and apart:
        # an effect a data sheet of the car mimics (bench/separable.py) cannot be told from that sheet by any tool:
        # there "the data sheet is off" (base_parameters) is a right answer too, an unrelated effect is not
        stands = [o for o in mixed if apart.get(o.case.name, 0.0) >= SEPARABLE_SIGMA]
        mimic = [o for o in mixed if o not in stands]
        print("  [info] each effect's signature beyond the best effect-free data sheet (generator's equations): "
              + ", ".join(f"{o.case.name.split('_', 2)[2]} {apart.get(o.case.name, float('nan')):.1f} sigma"
                          for o in mixed))
        share(f">= 85 % named correctly where the effect stands out from any data sheet by >= {SEPARABLE_SIGMA:.0f} "
              "sigma", sum(o in right for o in stands), len(stands), 0.85)
        fine = [o for o in mimic if o in right or o.diag.status == "base_parameters"
                or (o.diag.status not in CONFIDENT and o not in wrong)]
        print(f"  [info] effects a data sheet mimics (< {SEPARABLE_SIGMA:.0f} sigma): named or answered "
              f"\"data sheet off\" or abstained {pct(len(fine), len(mimic))}")
        told = [o for o in mixed if o.diag.status == "base_parameters" and set(o.case.expected) <= set(o.diag.mimicked)]
        print(f"  [info] effect drives answered base_parameters whose report names the drive's effect as one that "
              f"would change the log alike on a right data sheet (mimicked_by): {len(told)} of "
              f"{sum(o.diag.status == 'base_parameters' for o in mixed)}")
    none = [o for o in out if o.case.kind == "none"]
    quiet = [o for o in none if o.diag.status not in (*CONFIDENT, "ambiguous", "base_parameters")
             and not o.diag.base_named and not (o.ident and o.ident.named)]
    share(">= 95 % no-effect drives with no attribution of any kind (diagnosis and identify)", len(quiet), len(none),
          0.95)
    cpu = [o.diag.cpu_s * 60.0 / o.case.duration_s for o in out if np.isfinite(o.diag.cpu_s)]
    if cpu:
        print(f"  CPU seconds per diagnose (per 60 s of log): median {np.median(cpu):.1f}, max {np.max(cpu):.1f}")
        check(f"diagnose <= {CPU_DIAGNOSE_S:.0f} s CPU per 60 s log", max(cpu) <= CPU_DIAGNOSE_S,
              f"max {max(cpu):.1f} s")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--set", choices=IDENTIFY_SETS, default="idev", dest="which")
    ap.add_argument("--quick", action="store_true", help="9 cases, 40 s drives")
    ap.add_argument("--jobs", type=int, default=1, help="worker processes")
    ap.add_argument("--case", action="append", default=[], help="only the case of this name (repeatable)")
    ap.add_argument("--generate-only", action="store_true", help="make (or check) the cached drives and stop")
    ap.add_argument("--no-separable", action="store_true",
                    help="skip bench/separable.py's step (tens of minutes per set): the targets that need each "
                         "effect's signature beyond the best data sheet are not printed")
    args = ap.parse_args()
    folder, todo = generate(args.which, args.quick, args.jobs, args.case)
    if args.case and not todo:
        print(f"no case named {args.case}", file=sys.stderr)
        return 2
    if args.generate_only:
        print(f"{len(todo)} cases in {folder}")
        for c in todo:
            t = c.truth
            print(f"  {c.name[:44]:44s} {c.car:11s} {c.rate_hz:6.1f} Hz  stiffness {t['stiffness']:7.1f} N m/rad "
                  f"({t['stiffness'] / t['stiffness_nominal']:.3f}x)  mode {t['freq_hz']:5.2f} Hz zeta {t['zeta']:.3f} "
                  f"(nominal {t['freq_hz_nominal']:5.2f} Hz, {t['zeta_nominal']:.3f})  mass {t['mass']:6.1f} kg  "
                  f"lash {t['lash_mrad']:6.1f} mrad  {c.signal_sigma:6.1f} sigma")
        return 0
    print(f"independent-generator identification benchmark, set {args.which}: {len(todo)} cases, "
          f"{todo[0].duration_s:.0f} s drives, BLF through {DBC.name}")
    if identify_logs is None:
        print(f"identification unavailable ({UNAVAILABLE}): only the diagnosis is scored")
    out: list[Outcome] = []
    with ProcessPoolExecutor(max_workers=args.jobs) if args.jobs > 1 else Serial() as pool:
        for i, o in enumerate(pool.map(run, todo, [folder] * len(todo))):
            out.append(o)
            print(f"[{i + 1:2d}/{len(todo)}] {line(o)}", flush=True)
    # base_effect cases, by the generator's own equations (cached)
    apart = None if args.no_separable else separable(folder, todo)
    print("\ntargets")
    if identify_logs is None:
        print(f"  [n/a] identification targets: identification unavailable ({UNAVAILABLE})")
    else:
        identification_targets(out)
    diagnosis_targets(out, apart)
    if len(out) < 30:
        print(f"  (only {len(out)} drives: the targets are stated for the full set; run without --quick)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
