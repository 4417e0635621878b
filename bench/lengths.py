"""Diagnosis and identification cost per log length, and the staged answers against those on every event.

Used by ``bench/diagnosis.py --lengths`` (the project's own truth drives) and ``bench/diagnosis_indep.py
--lengths`` (the independent generator's). For each truth and each length (60 s, 10 min, 30 min by default)
the log is diagnosed twice: with the sequential design (the default of ``diagnose``) and with
``--all-events`` (one stage of every event); and identified twice, staged (``identify``'s default) and on
every event. Printed per run: events used of the log's, CPU and wall seconds, the decision or the named
parameters; then the ratio of the costs, whether the answers agree, and the issue's targets (a 60 s log in
<= 15 s CPU, a 30-minute drive diagnosed and identified in <= 90 s wall, the same answers on the subset as
on all events).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
from app.errors import AppError
from app.identify import identify_events, identify_staged
from app.identify.logs import prepared_logs
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
    ident_staged: Run | None = None  # identify on the log (None: not identifiable, see ``ident_note``)
    ident_whole: Run | None = None
    ident_note: str = ""


def _identify(signals: SignalSet, vehicle: Vehicle, staged: bool) -> Run:
    events, noise, _ = prepared_logs([("log", signals)], DIAGNOSIS_EVENTS)
    c0, w0 = time.process_time(), time.perf_counter()
    ident = (identify_staged if staged else identify_events)(events, noise, vehicle)
    cpu, wall = time.process_time() - c0, time.perf_counter() - w0
    head = ident.fit_log[0] if ident.fit_log and ident.fit_log[0].startswith("sequential design") else "one stage"
    return Run(ident.n_events, len(events), cpu, wall, "named " + (",".join(sorted(ident.named)) or "-"), head)


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


def threads_line(signals: SignalSet, vehicle: Vehicle, repeat: int = 5) -> str:
    """One simulator pass over the log's event clusters, serial against side by side on threads (wall and CPU)."""
    import app.analysis.diagnosis.forward as forward
    from app.analysis.diagnosis.prepare import prepare
    from app.analysis.events import detect_events

    events, _, _ = prepare(signals, detect_events(signals, DIAGNOSIS_EVENTS))
    forward.simulate_events(events, vehicle, 1.0)  # compiled and warm
    keep = forward.SIM_THREADS
    got = {}
    try:
        for threads in (1, max(keep, 2)):
            forward.SIM_THREADS = threads
            c0, w0 = time.process_time(), time.perf_counter()
            for _ in range(repeat):
                forward.simulate_events(events, vehicle, 1.0)
            got[threads] = (time.perf_counter() - w0, time.process_time() - c0)
    finally:
        forward.SIM_THREADS = keep
    (w1, c1), (wn, cn) = got[1], got[max(keep, 2)]
    return (f"simulator pass over {len(forward.clusters(events))} clusters ({len(events)} events), {repeat} passes: "
            f"serial {w1:.2f} s wall {c1:.2f} s CPU, {max(keep, 2)} threads {wn:.2f} s wall {cn:.2f} s CPU: "
            f"wall ratio {w1 / max(wn, 1e-9):.2f}")


def measure(truths: Sequence[tuple[str, Callable[[float], SignalSet]]], vehicle: Vehicle, options: DiagnosisOptions,
            lengths: Sequence[float] = LENGTHS_S, whole: bool = True) -> list[Row]:
    """Each truth's log of each length (``make(length_s)``) diagnosed staged and, with ``whole``, on all events."""
    rows = []
    for name, make in truths:
        for length in lengths:
            signals = make(length)
            if not rows:
                print("  " + threads_line(signals, vehicle), flush=True)
            staged = _run(signals, vehicle, replace(options, sequential=True))
            every = _run(signals, vehicle, replace(options, sequential=False)) if whole else None
            try:
                i_staged = _identify(signals, vehicle, True)
                i_whole = _identify(signals, vehicle, False) if whole else None
                note = ""
            except AppError as exc:
                i_staged = i_whole = None
                note = f"{type(exc).__name__}: {exc}"
            row = Row(name, length, staged, every, i_staged, i_whole, note)
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
    if r.ident_staged is not None:
        i = r.ident_staged
        out += (f"\n  {'':28s} {'':9s}  identify: {i.events_used:4d}/{i.events_total:<4d} events {i.cpu_s:6.1f} s CPU "
                f"{i.wall_s:6.1f} s wall  {i.decision:28s}")
        if r.ident_whole is not None:
            w = r.ident_whole
            out += (f" | all events: {w.cpu_s:6.1f} s CPU  {w.decision:28s} "
                    f"{'same' if w.decision == i.decision else 'DIFFERENT'}")
    elif r.ident_note:
        out += f"\n  {'':28s} {'':9s}  identify: {r.ident_note[:120]}"
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
    long = [r.staged.wall_s + (r.ident_staged.wall_s if r.ident_staged else 0.0) for r in rows if r.length_s >= 1800.0]
    if long:
        ok = max(long) <= WALL_30MIN_MAX
        cpu = max(r.staged.cpu_s + (r.ident_staged.cpu_s if r.ident_staged else 0.0)
                  for r in rows if r.length_s >= 1800.0)
        print(f"  [{'PASS' if ok else 'FAIL'}] a 30-minute drive diagnosed and identified in <= {WALL_30MIN_MAX:.0f} s "
              f"wall: max {max(long):.1f} s (wall on this machine as loaded; CPU max {cpu:.1f} s)")
    both = [r for r in rows if r.whole is not None]
    if both:
        agree = sum(r.whole is not None and r.whole.decision == r.staged.decision for r in both)
        print(f"  [{'PASS' if agree == len(both) else 'FAIL'}] the decision on the subset equals the decision on all "
              f"events: {agree}/{len(both)}")
    idents = [r for r in rows if r.ident_staged is not None and r.ident_whole is not None]
    if idents:
        agree = sum(r.ident_whole is not None and r.ident_staged is not None
                    and r.ident_whole.decision == r.ident_staged.decision for r in idents)
        print(f"  [{'PASS' if agree == len(idents) else 'FAIL'}] the parameters named on the subset equal those named "
              f"on all events: {agree}/{len(idents)}")
