"""Diagnosis cost per log length, and the sequential design's decision against the decision on every event.

Used by ``bench/diagnosis.py --lengths`` (the project's own truth drives) and ``bench/diagnosis_indep.py
--lengths`` (the independent generator's). For each truth and each length (60 s, 10 min, 30 min by default) the
log is diagnosed twice: with the sequential design (the default of ``diagnose``) and with ``--all-events``
(one stage of every event). Printed per run: events used of the log's, CPU and wall seconds, the decision; then
the ratio of the two costs and whether the decisions agree, and the issue's targets (a 60 s log in <= 15 s CPU,
a 30-minute drive in <= 90 s wall, the same decision on the subset as on all events).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals
from app.signals import SignalSet
from sim import Vehicle

LENGTHS_S = (60.0, 600.0, 1800.0)
CPU_60S_MAX = 15.0  # s CPU for a 60 s log
WALL_30MIN_MAX = 90.0  # s wall for a 30-minute drive


@dataclass(frozen=True)
class Run:
    events_used: int
    events_total: int
    cpu_s: float
    wall_s: float
    decision: str
    stages: str


@dataclass(frozen=True)
class Row:
    truth: str
    length_s: float
    staged: Run
    whole: Run | None  # None: the all-events run was skipped


def _run(signals: SignalSet, vehicle: Vehicle, options: DiagnosisOptions) -> Run:
    c0, w0 = time.process_time(), time.perf_counter()
    res = diagnose_signals(signals, vehicle, options)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    d = res.decision
    label = f"{d.status} {'+'.join(d.top)}".rstrip()
    stages = res.fit_order[0] if res.fit_order and res.fit_order[0].startswith("sequential design") else "one stage"
    used = len(res.events)
    left = sum(1 for s in res.skipped if "sequential design stopped" in str(s.get("reason", "")))
    return Run(used, used + left, cpu, wall, label, stages)


def measure(truths: Sequence[tuple[str, Callable[[float], SignalSet]]], vehicle: Vehicle, options: DiagnosisOptions,
            lengths: Sequence[float] = LENGTHS_S, whole: bool = True) -> list[Row]:
    """Each truth's log of each length (``make(length_s)``) diagnosed staged and, with ``whole``, on all events."""
    rows = []
    for name, make in truths:
        for length in lengths:
            signals = make(length)
            staged = _run(signals, vehicle, replace(options, sequential=True))
            every = _run(signals, vehicle, replace(options, sequential=False)) if whole else None
            row = Row(name, length, staged, every)
            rows.append(row)
            print(line(row), flush=True)
    return rows


def line(r: Row) -> str:
    s = r.staged
    out = (f"  {r.truth[:28]:28s} {r.length_s / 60:5.1f} min  staged: {s.events_used:4d}/{s.events_total:<4d} events "
           f"{s.cpu_s:6.1f} s CPU {s.wall_s:6.1f} s wall  {s.decision:28s}")
    if r.whole is not None:
        w = r.whole
        same = "same" if w.decision == s.decision else "DIFFERENT"
        out += (f" | all events: {w.cpu_s:6.1f} s CPU {w.wall_s:6.1f} s wall  {w.decision:28s} {same}, "
                f"CPU ratio {w.cpu_s / max(s.cpu_s, 1e-9):4.2f}")
    return out


def report(rows: Sequence[Row]) -> None:
    """The per-length summary and the targets."""
    print("\nper log length (staged: the sequential design; ratio: all-events CPU over staged CPU)")
    for length in sorted({r.length_s for r in rows}):
        at = [r for r in rows if r.length_s == length]
        cpu = [r.staged.cpu_s for r in at]
        wall = [r.staged.wall_s for r in at]
        text = (f"  {length / 60:5.1f} min: {len(at)} logs, staged CPU median {sorted(cpu)[len(cpu) // 2]:.1f} s "
                f"max {max(cpu):.1f} s, wall max {max(wall):.1f} s")
        whole = [r for r in at if r.whole is not None]
        if whole:
            agree = sum(r.whole is not None and r.whole.decision == r.staged.decision for r in whole)
            ratio = [r.whole.cpu_s / max(r.staged.cpu_s, 1e-9) for r in whole if r.whole is not None]
            text += (f"; all events CPU max {max(r.whole.cpu_s for r in whole if r.whole is not None):.1f} s, "
                     f"ratio median {sorted(ratio)[len(ratio) // 2]:.2f}; decisions agree {agree}/{len(whole)}")
        print(text)
    print("targets")
    short = [r.staged.cpu_s for r in rows if r.length_s <= 60.0]
    if short:
        ok = max(short) <= CPU_60S_MAX
        print(f"  [{'PASS' if ok else 'FAIL'}] a 60 s log diagnosed in <= {CPU_60S_MAX:.0f} s CPU: "
              f"max {max(short):.1f} s")
    long = [r.staged.wall_s for r in rows if r.length_s >= 1800.0]
    if long:
        ok = max(long) <= WALL_30MIN_MAX
        print(f"  [{'PASS' if ok else 'FAIL'}] a 30-minute drive diagnosed in <= {WALL_30MIN_MAX:.0f} s wall: "
              f"max {max(long):.1f} s (wall on this machine as loaded; CPU max "
              f"{max(r.staged.cpu_s for r in rows if r.length_s >= 1800.0):.1f} s)")
    both = [r for r in rows if r.whole is not None]
    if both:
        agree = sum(r.whole is not None and r.whole.decision == r.staged.decision for r in both)
        print(f"  [{'PASS' if agree == len(both) else 'FAIL'}] the decision on the subset equals the decision on all "
              f"events: {agree}/{len(both)}")
