"""Printing for bench/diagnosis.py: confusion matrix, rates, targets, the 100 Hz / 1 kHz comparison."""

from __future__ import annotations

from collections import Counter, defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np

from sim.effects import EFFECTS

CONFIDENT = ("explained", "partial")


@dataclass
class Outcome:
    case: Any  # bench.diagnosis.Case
    status: str
    top: tuple[str, ...]
    confusable: tuple[str, ...]
    clear: bool
    signal_ratio: float
    shrink: float
    oracle: float
    second_drive: float
    elapsed: float
    n_events: int
    fitted: dict[str, float]
    gap_samples: float  # median speed samples inside the gap-traverse phase (held-out events)
    left: dict[str, float]  # remaining residual-to-noise ratio of each single candidate


def pct(a: int, b: int) -> str:
    return f"{100 * a / b:5.1f} % ({a}/{b})" if b else "  n/a"


def col(o: Outcome) -> str:
    return o.top[0] if o.status in CONFIDENT else o.status


def _rates(group: list[Outcome]) -> tuple[list[Outcome], list[Outcome], list[Outcome]]:
    confident = [o for o in group if o.status in CONFIDENT]
    correct = [o for o in confident if o.top[0] == o.case.truth]
    wrong = [o for o in confident if o.top[0] != o.case.truth]
    abstain = [o for o in group if o.status not in CONFIDENT]
    return correct, wrong, abstain


def confusion(outs: list[Outcome]) -> None:
    lib = list(EFFECTS)
    cols = [*lib, "ambiguous", "none_of_candidates", "no_significant_gap", "insufficient_data"]
    rows: dict[str, Counter[str]] = defaultdict(Counter)
    for o in outs:
        label = {"in_library": o.case.truth, "faint": f"faint {o.case.truth}", "none": "(no effect)",
                 "loo": f"LOO {o.case.truth}"}[o.case.kind]
        rows[str(label)][col(o)] += 1
    print("\nconfusion matrix (rows: truth; columns: decision -- attributed effect or status)")
    print(f"{'':28s}" + "".join(f"{c[:12]:>13s}" for c in cols))
    for r, cnt in rows.items():
        print(f"{r:28s}" + "".join(f"{cnt.get(c, 0):13d}" for c in cols))


def report(outs: list[Outcome], clear_ratio: float, faint_range: tuple[float, float]) -> None:
    confusion(outs)
    single = [o for o in outs if o.case.kind == "in_library"]
    clear = [o for o in single if o.clear]
    correct, wrong, abstain = _rates(clear)
    amb_with_truth = [o for o in abstain if o.status == "ambiguous" and o.case.truth in o.confusable]
    none = [o for o in outs if o.case.kind == "none"]
    none_attr = [o for o in none if o.status in (*CONFIDENT, "ambiguous")]
    loo = [o for o in outs if o.case.kind == "loo"]
    loo_expl = [o for o in loo if o.status == "explained"]
    loo_attr = [o for o in loo if o.status in CONFIDENT]
    print(f"\nsingle in-library effects: {len(single)} cases, {len(clear)} with a clear signal "
          f"(truth-vs-nominal RMS >= {clear_ratio:g} noise sigma)")
    print(f"  correct-confident {pct(len(correct), len(clear))}   wrong-confident {pct(len(wrong), len(clear))}   "
          f"abstain {pct(len(abstain), len(clear))} (of which ambiguous naming the truth: {len(amb_with_truth)})")
    n_expl = sum(o.status == "explained" for o in correct)
    print(f"  of the correct: explained {n_expl}, partial {len(correct) - n_expl} (a partial correct attribution "
          f"left a remainder distinguishable from noise)")
    for o in [o for o in single if not o.clear]:
        print(f"  not clear: {o.case.truth} signal {o.signal_ratio:.1f} -> {col(o)}")
    faint = [o for o in outs if o.case.kind == "faint"]
    if faint:
        f_corr, f_wrong, f_abst = _rates(faint)
        f_amb = [o for o in f_abst if o.status == "ambiguous" and o.case.truth in o.confusable]
        ratios = [o.signal_ratio for o in faint]
        print(f"faint in-library effects ({len(faint)} cases, truth-vs-nominal RMS aimed at {faint_range[0]:g}-"
              f"{faint_range[1]:g} noise sigma, got {min(ratios):.1f}-{max(ratios):.1f}):")
        print(f"  correct-confident {pct(len(f_corr), len(faint))}   wrong-confident {pct(len(f_wrong), len(faint))}   "
              f"abstain {pct(len(f_abst), len(faint))} (ambiguous naming the truth: {len(f_amb)}; "
              f"{', '.join(f'{k} {v}' for k, v in sorted(Counter(o.status for o in f_abst).items()))})")
        for o in f_wrong:
            print(f"  faint wrong: truth {o.case.truth} (signal {o.signal_ratio:.1f}) -> {o.status} {'+'.join(o.top)}")
    print(f"no-effect drives: any attribution {pct(len(none_attr), len(none))}  "
          f"({', '.join(o.status for o in none)})")
    print(f"leave-one-effect-out: false 'explained' {pct(len(loo_expl), len(loo))}, any confident attribution "
          f"{pct(len(loo_attr), len(loo))}, ambiguous {sum(o.status == 'ambiguous' for o in loo)}")
    shrinks = [o.shrink for o in correct]
    oracles = [o.oracle for o in correct]
    second = [o.second_drive for o in correct if np.isfinite(o.second_drive)]
    med = float(np.median(shrinks)) if shrinks else float("nan")
    print(f"held-out shrink when correctly attributed: median {100 * med:.1f} % (oracle: true effect's own fit, "
          f"median {100 * float(np.median(oracles)) if oracles else float('nan'):.1f} %)")
    print(f"shrink on a second withheld drive: median {100 * float(np.median(second)) if second else float('nan'):.1f} "
          f"% over {len(second)} cases")
    errs: dict[str, list[float]] = defaultdict(list)
    for o in correct:
        for p in EFFECTS[str(o.case.truth)].params:
            if p.name in o.fitted:
                errs[f"{o.case.truth}.{p.name}"].append(abs(o.fitted[p.name] - o.case.values[p.name]) / (p.hi - p.lo))
    if errs:
        print("parameter recovery (|fitted - true| / prior range, median over correct cases): "
              + ", ".join(f"{k} {100 * float(np.median(v)):.1f} %" for k, v in errs.items()))
    for o in [o for o in clear if o not in correct]:
        print(f"  miss: truth {o.case.truth} {o.case.values} (signal {o.signal_ratio:.1f}) -> {o.status} "
              f"{'+'.join(o.top)} {'/'.join(o.confusable)}")
    for o in loo_expl:
        print(f"  LOO false explained: truth {o.case.truth} -> {'+'.join(o.top)}")
    times = [o.elapsed for o in outs]
    print(f"diagnosis CPU time per log: median {np.median(times):.1f} s, max {np.max(times):.1f} s "
          f"(events per log: median {np.median([o.n_events for o in outs]):.0f})")

    def check(name: str, ok: bool, value: str) -> None:
        print(f"  [{'PASS' if ok else 'FAIL'}] {name}: {value}")

    print("\ntargets")
    n = max(len(clear), 1)
    check(">= 85 % correct-confident (single, clear signal)", len(correct) / n >= 0.85, pct(len(correct), len(clear)))
    check("<= 5 % wrong-confident", len(wrong) / n <= 0.05, pct(len(wrong), len(clear)))
    check("<= 5 % any attribution with no effect", len(none_attr) <= 0.05 * max(len(none), 1),
          pct(len(none_attr), len(none)))
    check("<= 5 % false 'explained' with the truth outside the library", len(loo_expl) <= 0.05 * max(len(loo), 1),
          pct(len(loo_expl), len(loo)))
    check("median held-out shrink >= 70 % when correctly attributed", med >= 0.7, f"{100 * med:.1f} %")


def report_rates(outs: list[Outcome]) -> None:
    """The same drives recorded at 100 Hz and at 1 kHz, side by side."""
    if not outs:
        return
    print("\n100 Hz vs 1 kHz (same truth drives; gap samples: median speed samples inside the gap-traverse phase "
          "of held-out events; left: remaining residual-to-noise of torque_lag / speed_sensor)")
    print(f"{'case':26s} {'rate':5s} {'gap samples':>11s}  {'decision':34s} {'left lag/sensor':>16s}")
    for o in outs:
        name = f"{o.case.kind} {o.case.truth or '-'}"
        left = "/".join(f"{o.left[k]:.2f}" if k in o.left else "-" for k in ("torque_lag", "speed_sensor"))
        dec = f"{o.status} {'+'.join(o.top)} {'/'.join(o.confusable)}".strip()
        print(f"{name:26s} {o.case.rate:5s} {o.gap_samples:11.1f}  {dec:34s} {left:>16s}")
