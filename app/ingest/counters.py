"""Alive/rolling counters: learn each counter's pattern from the data, then count deviations.

Counters in production DBCs do not all count 0, 1, 2, ...: some step by 2, 4 or 16 (a gateway
forwarding every other frame, a counter in the upper nibble), some count down, some stop short
of the top value (0..14), some skip a value, some run two nibbles of a byte in opposite
directions, some are constant in a log because the function is off. The DBC says none of this,
so the pattern is learned from the values themselves, window by window (``WINDOW`` values):

* **step**: the most common non-zero step modulo ``2**length``; the modulus from the
  wrap-arounds (a step of +s that wraps from v to v' means modulus v + s - v'; counting down,
  v' - v + s), else the DBC range (:func:`dbc_modulus`).
* **sequence**: the most common successor of every value, when the successors close into one
  cycle, each seen at least twice (e.g. the two-nibble byte above).
* **constant**: one value throughout (not counting in this stretch of the log, not "stuck").

Candidates are scored by the share of steps they explain (the previous window's pattern first,
so a pattern only changes when another one explains more); the best one must explain
``MIN_FIT`` of the window's steps. A window no pattern fits is split in halves down to
``RUN`` steps (so a change of pattern, e.g. an ECU counting down after a state change, is
isolated), and the rest is "unchecked". Inside a fitting window, ``RUN`` or more deviating
steps in a row are re-examined the same way: they are a different pattern, not lost frames.

With a pattern of ``P`` values each step advances ``k`` positions along the cycle: ``k == 1``
is normal, ``k == 0`` a repeat, ``k > 1`` a gap of ``k - 1`` missed frames; a value off the
cycle is a gap of unknown size.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from cantools.database.can import Signal as CanSignal

I64 = npt.NDArray[np.int64]

WINDOW = 256  # values learned from at a time
MIN_FIT = 0.9  # share of a window's steps a pattern must explain
RUN = 8  # this many deviating steps in a row are examined as a pattern of their own


def dbc_modulus(sig: CanSignal) -> int:
    """The counting range the DBC implies: ``maximum + 1`` when it stops short of the top, else ``2**length``."""
    top = 2 ** sig.length
    if isinstance(sig.maximum, (int, float)) and 0 < sig.maximum < top - 1 and float(sig.maximum).is_integer():
        return int(sig.maximum) + 1
    return top


@dataclass(frozen=True, slots=True, eq=False)
class Pattern:
    """A counting pattern: the values in counting order and a value -> position table."""

    kind: str  # "step", "sequence" or "constant"
    cycle: I64  # (P,) values in counting order
    pos: I64  # (2**length,) position of each value in ``cycle``; -1 off the cycle
    modulus: int  # step: the counting range; sequence/constant: P
    step: int | None  # step: signed advance per frame (modulo ``modulus``); else None

    @staticmethod
    def of(kind: str, cycle: list[int] | I64, width: int, modulus: int, step: int | None = None) -> Pattern:
        values = np.asarray(cycle, np.int64)
        pos = np.full(width, -1, np.int64)
        pos[values] = np.arange(values.size)
        return Pattern(kind, values, pos, modulus, step)

    def same(self, other: Pattern | None) -> bool:
        return other is not None and self.kind == other.kind and np.array_equal(self.cycle, other.cycle)

    def describe(self) -> str:
        if self.kind == "step":
            return f"step {self.step:+d} mod {self.modulus}"
        if self.kind == "sequence":
            return f"sequence of {self.cycle.size} values"
        return f"constant {int(self.cycle[0])}"


@dataclass(slots=True)
class Steps:
    """How each step of a value sequence relates to a pattern; arrays of shape ``(n - 1,)``."""

    normal: npt.NDArray[np.bool_]
    repeat: npt.NDArray[np.bool_]
    gap: npt.NDArray[np.bool_]
    missed: I64  # frames lost at each gap (0 when unknown or no gap)

    @staticmethod
    def of(seq: I64, pattern: Pattern) -> Steps:
        p = pattern.pos[seq]
        size = pattern.cycle.size
        on = (p[1:] >= 0) & (p[:-1] >= 0)
        k = np.where(on, np.mod(p[1:] - p[:-1], size), -1)
        normal = k == (1 if size > 1 else 0)
        repeat = (seq[1:] == seq[:-1]) & ~normal
        gap = ~normal & ~repeat
        return Steps(normal, repeat, gap, np.where(gap & (k > 1), k - 1, 0))

    def fit(self) -> float:
        return float(self.normal.mean()) if self.normal.size else 0.0


def _step_pattern(seq: I64, width: int, hint: int) -> Pattern | None:
    d = np.mod(np.diff(seq), width)
    d = d[d != 0]
    if not d.size:
        return None
    s_w = int(np.bincount(d).argmax())
    a, b = seq[:-1], seq[1:]
    top = int(seq.max())
    if s_w <= width // 2:  # counting up: a wrap goes from a to a + s - M
        cand = (a + s_w - b)[b < a]
    else:  # counting down by t: a wrap goes from a to a - t + M
        cand = (b - a + (width - s_w))[b > a]
    cand = cand[(cand > top) & (cand <= width)]
    modulus = int(np.bincount(cand).argmax()) if cand.size else min(width, max(hint, top + 1))
    step = s_w % modulus if s_w <= width // 2 else (modulus - (width - s_w)) % modulus
    if step == 0:
        return None
    n = modulus // math.gcd(step, modulus)
    start = int(np.bincount(seq).argmax()) % modulus  # the most common value: a glitch cannot shift the orbit
    cycle = (start + step * np.arange(n, dtype=np.int64)) % modulus
    signed = step if step <= modulus // 2 else step - modulus
    return Pattern.of("step", cycle, width, modulus, signed)


def _sequence_pattern(seq: I64, width: int) -> Pattern | None:
    a, b = seq[:-1], seq[1:]
    moved = a != b
    if not moved.any():
        return None
    counts = np.bincount(a[moved] * width + b[moved], minlength=width * width).reshape(width, width)
    has = counts.max(axis=1) > 0
    succ = counts.argmax(axis=1)
    start = int(np.bincount(seq, minlength=width)[has].argmax())
    start = int(np.flatnonzero(has)[start])
    # every link must be seen at least twice, else a window holding each value once would learn its own gaps
    support = counts.max(axis=1) >= 2
    cycle, seen, u = [start], {start}, int(succ[start])
    if not support[start]:
        return None
    while u != start:
        if not support[u] or u in seen:
            return None  # the successors do not close into one cycle
        cycle.append(u)
        seen.add(u)
        u = int(succ[u])
    if len(cycle) < 2:
        return None
    return Pattern.of("sequence", cycle, width, len(cycle))


def candidates(seq: I64, width: int, hint: int, previous: Pattern | None = None) -> list[Pattern]:
    """Patterns worth scoring on ``seq``: the previous one, step, sequence, constant (in that order)."""
    out = [] if previous is None else [previous]
    for p in (_step_pattern(seq, width, hint), _sequence_pattern(seq, width)):
        if p is not None:
            out.append(p)
    mode = int(np.bincount(seq, minlength=width).argmax())
    out.append(Pattern.of("constant", [mode], width, 1))
    return out


def best_pattern(seq: I64, width: int, hint: int, previous: Pattern | None = None) -> tuple[Pattern, Steps]:
    """The candidate explaining most steps of ``seq`` (ties go to the earlier candidate).

    A previous pattern that explains every step cannot be beaten (ties go to it), so the
    other candidates are not even built: the common case costs one table lookup per value.
    """
    if previous is not None:
        steps = Steps.of(seq, previous)
        if steps.normal.all():
            return previous, steps
    best: tuple[Pattern, Steps] | None = None
    for p in candidates(seq, width, hint, previous):
        steps = Steps.of(seq, p)
        if best is None or steps.fit() > best[1].fit():
            best = (p, steps)
    assert best is not None  # the constant candidate always exists
    return best


def long_runs(flags: npt.NDArray[np.bool_], length: int) -> list[tuple[int, int]]:
    """``[start, stop)`` of every run of at least ``length`` True values."""
    edges = np.diff(np.r_[0, flags.astype(np.int8), 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(int(a), int(b)) for a, b in zip(starts, stops, strict=True) if b - a >= length]


@dataclass(slots=True)
class CounterGaps:
    """What one counter (message, signal, bus) showed over the log."""

    message: str
    signal: str
    channel: int
    frames: int
    modulus: int  # of the main pattern (step: counting range; sequence: values per cycle); else the DBC's
    gaps: int  # steps that skip ahead along the pattern (or land off it)
    missed: int  # frames lost according to the counter
    repeats: int  # steps of zero where the pattern moves on
    first_gap_s: float | None
    kind: str = "unknown"  # main pattern: "step", "sequence", "constant", "irregular" (none fits), "unknown"
    pattern: str = ""  # e.g. "step +1 mod 15", "sequence of 16 values", "constant 0"
    step: int | None = None  # signed step of a "step" pattern
    fit: float | None = None  # share of the checked steps that follow their pattern
    pattern_changes: int = 0  # the counter switched to another pattern (e.g. counting down after a state change)
    unchecked: int = 0  # steps in stretches no pattern explains: not judged


class CounterTrack:
    """Streamed values of one counter on one bus -> :class:`CounterGaps` (memory: one window)."""

    def __init__(self, message: str, signal: str, channel: int, length: int, hint: int) -> None:
        self.width = 1 << length
        self.hint = hint
        self._v: list[I64] = []
        self._t: list[I64] = []
        self._n = 0
        self._anchor: tuple[int, int] | None = None  # last value and time of the previous window
        self._pattern: Pattern | None = None
        self._by_pattern: dict[str, tuple[Pattern, int]] = {}  # description -> (pattern, steps checked)
        self._normal = 0
        self.result = CounterGaps(message, signal, channel, 0, hint, 0, 0, 0, None)

    def feed(self, values: npt.NDArray[np.floating], t_ns: I64) -> None:
        """Append finite counter values (raw integers as floats) and their times (ns)."""
        if not values.size:
            return
        self._v.append(values.astype(np.int64))
        self._t.append(np.asarray(t_ns, np.int64))
        self._n += values.size
        self.result.frames += int(values.size)
        while self._n >= WINDOW:
            if not self._verify_in_bulk():
                self._flush(WINDOW)

    def _verify_in_bulk(self) -> bool:
        """Count the whole windows that follow the current pattern perfectly, all at once.

        Window by window, each of them would choose the current pattern (it explains every
        step, and ties go to it) and count no gap, so counting them together gives the same
        result. Returns False when not even the first buffered window is perfect.
        """
        if self._pattern is None or self._anchor is None:
            return False
        v = self._v[0] if len(self._v) == 1 else np.concatenate(self._v)
        pos = self._pattern.pos
        p = pos[v]
        prev = np.r_[pos[self._anchor[0]], p[:-1]]
        size = self._pattern.cycle.size
        normal = (p >= 0) & (prev >= 0) & (np.mod(p - prev, size) == (1 if size > 1 else 0))
        bad = np.flatnonzero(~normal)
        perfect = int(bad[0]) if bad.size else v.size
        done = min(perfect, v.size) // WINDOW * WINDOW
        if not done:
            if len(self._v) > 1:
                self._v, self._t = [v], [np.concatenate(self._t)]
            return False
        t = self._t[0] if len(self._t) == 1 else np.concatenate(self._t)
        self._normal += done  # no gaps, repeats or pattern changes in a perfect stretch
        key = self._pattern.describe()
        self._by_pattern[key] = (self._pattern, self._by_pattern[key][1] + done)
        self._v, self._t, self._n = [v[done:]], [t[done:]], v.size - done
        self._anchor = (int(v[done - 1]), int(t[done - 1]))
        return True

    def finish(self) -> CounterGaps:
        """Judge what is still buffered and summarise (call once, at the end)."""
        if self._n:
            self._flush(self._n, final=True)
        r = self.result
        checked = sum(n for _, n in self._by_pattern.values())
        if self._by_pattern:
            main, _ = max(self._by_pattern.values(), key=lambda pn: pn[1])
            r.kind, r.pattern, r.step, r.modulus = main.kind, main.describe(), main.step, main.modulus
            r.fit = self._normal / checked if checked else None
        elif r.unchecked:
            r.kind, r.pattern = "irregular", "irregular"
        return r

    def _flush(self, n: int, final: bool = False) -> None:
        v, t = np.concatenate(self._v), np.concatenate(self._t)
        seq, ts = v[:n], t[:n]
        if self._anchor is not None:
            seq, ts = np.r_[self._anchor[0], seq], np.r_[self._anchor[1], ts]
        carry = self._examine(seq, ts, final) if seq.size >= 2 else 0
        if carry >= n:  # cannot happen (a carry is at most a tenth of a fitting piece); never loop
            carry = self._examine(seq, ts, True)
        done = n - carry
        self._v, self._t, self._n = [v[done:]], [t[done:]], v.size - done
        self._anchor = (int(v[done - 1]), int(t[done - 1]))

    def _examine(self, seq: I64, ts: I64, final: bool) -> int:
        """Judge the steps of ``seq``; returns how many trailing values were left for the next data.

        Deviating steps at the very end are left for later (unless ``final``): they may be the
        start of another pattern, which only the following values can show.
        """
        pattern, steps = best_pattern(seq, self.width, self.hint, self._pattern)
        nsteps = seq.size - 1
        if steps.fit() < MIN_FIT:
            if nsteps >= 2 * RUN:  # isolate the change of pattern
                mid = seq.size // 2
                carry = self._examine(seq[: mid + 1], ts[: mid + 1], False)
                return self._examine(seq[mid - carry:], ts[mid - carry:], final)
            self.result.unchecked += nsteps
            return 0
        if not final:
            trailing = nsteps - int(np.flatnonzero(~steps.gap)[-1]) - 1  # fit >= MIN_FIT: some step is not a gap
            if trailing:
                self._examine(seq[: seq.size - trailing], ts[: seq.size - trailing], True)
                return trailing
        runs = long_runs(steps.gap, RUN)
        if not runs:
            self._count(seq, ts, pattern, steps)
            return 0
        edges = [0, *(e for run in runs for e in run), nsteps]
        for i, (a, b) in enumerate(itertools.pairwise(edges)):
            if b <= a:
                continue
            if i % 2:  # a run of deviations: perhaps another pattern
                self._examine(seq[a:b + 1], ts[a:b + 1], True)
            else:
                self._count(seq[a:b + 1], ts[a:b + 1], pattern, None)
        return 0

    def _count(self, seq: I64, ts: I64, pattern: Pattern, steps: Steps | None) -> None:
        steps = Steps.of(seq, pattern) if steps is None else steps
        r = self.result
        if self._pattern is not None and not pattern.same(self._pattern):
            r.pattern_changes += 1
        self._pattern = pattern
        gaps = int(steps.gap.sum())
        r.gaps += gaps
        r.missed += int(steps.missed.sum())
        r.repeats += int(steps.repeat.sum())
        if gaps and r.first_gap_s is None:
            r.first_gap_s = float(ts[int(np.argmax(steps.gap)) + 1]) / 1e9
        self._normal += int(steps.normal.sum())
        key = pattern.describe()
        prev = self._by_pattern.get(key)
        self._by_pattern[key] = (pattern, (prev[1] if prev else 0) + seq.size - 1)
