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

Learning is done window by window only where a counter starts or changes its pattern; the other
windows are judged in bulk, a whole chunk at once, against the current pattern
(:meth:`CounterTrack._verify_in_bulk`): a window is counted there only when the window-by-window
learning provably keeps the pattern and counts it as it stands, so the result is the same.
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
    """A counting pattern: the values in counting order, a value -> position and a value -> next value table."""

    kind: str  # "step", "sequence" or "constant"
    cycle: I64  # (P,) values in counting order
    pos: I64  # (2**length,) position of each value in ``cycle``; -1 off the cycle
    modulus: int  # step: the counting range; sequence/constant: P
    step: int | None  # step: signed advance per frame (modulo ``modulus``); else None
    succ: I64  # (2**length,) the value that follows each value of ``cycle``; -1 off the cycle

    @staticmethod
    def of(kind: str, cycle: list[int] | I64, width: int, modulus: int, step: int | None = None) -> Pattern:
        values = np.asarray(cycle, np.int64)
        pos = np.full(width, -1, np.int64)
        pos[values] = np.arange(values.size)
        succ = np.full(width, -1, np.int64)
        succ[values] = np.roll(values, -1)
        return Pattern(kind, values, pos, modulus, step, succ)

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


@dataclass(slots=True)
class _Plan:
    """The windows of one buffer judged at once against one pattern (see :meth:`CounterTrack._verify_in_bulk`).

    Window ``w`` holds the values ``base[off + w * WINDOW : off + (w + 1) * WINDOW]`` and its
    steps start from the value before it. Per window: whether the window-by-window learning
    would simply count it under ``pattern`` (``ok``), and cumulative sums (one leading zero) of
    what it counts, so a run of windows is counted with two lookups.
    """

    pattern: Pattern
    base: I64
    off: int
    ok: npt.NDArray[np.bool_]
    normal: I64
    gaps: I64
    missed: I64
    repeats: I64
    first_gap: I64  # per window: index in ``base`` of the value after its first gap; -1 without gaps

    @property
    def windows(self) -> int:
        return int(self.ok.size)


def _runs_at_least(flags: npt.NDArray[np.bool_], length: int) -> npt.NDArray[np.bool_]:
    """Per row of ``flags`` (2-D): True when the row holds a run of at least ``length`` True values."""
    rows, cols = flags.shape
    padded = np.zeros((rows, cols + 2), np.int8)
    padded[:, 1:-1] = flags
    edges = np.diff(padded.ravel())
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    out = np.zeros(rows, bool)
    out[starts[stops - starts >= length] // (cols + 2)] = True
    return out


def _step_candidate_normal(rows: I64, width: int, hint: int) -> I64:
    """Per row of ``rows`` (values, 2-D): steps the :func:`_step_pattern` candidate of that row explains.

    The same arithmetic as :func:`_step_pattern` (most common non-zero step, modulus from the
    wrap-arounds else the DBC hint, the orbit through the most common value), for many windows
    in one pass; -1 where it builds no candidate.
    """
    r = rows.shape[0]
    a, b = rows[:, :-1], rows[:, 1:]
    ri = np.arange(r, dtype=np.int64)[:, None]
    d = (b - a) & (width - 1)  # modulo the power of two, without an integer division
    hist = np.bincount((ri * width + d).ravel(), minlength=r * width).reshape(r, width)
    hist[:, 0] = 0  # zero steps do not vote
    moved = hist.any(axis=1)
    s_w = hist.argmax(axis=1)  # ties: the smallest step, as bincount().argmax()
    top = rows.max(axis=1)
    up = s_w <= width // 2
    cand = np.where(up[:, None], a + s_w[:, None] - b, b - a + (width - s_w)[:, None])
    valid = np.where(up[:, None], b < a, b > a) & (cand > top[:, None]) & (cand <= width)
    votes = np.bincount((ri * (width + 1) + cand)[valid], minlength=r * (width + 1)).reshape(r, width + 1)
    modulus = np.where(votes.any(axis=1), votes.argmax(axis=1), np.minimum(width, np.maximum(hint, top + 1)))
    step = np.where(up, np.mod(s_w, modulus), np.mod(modulus - (width - s_w), modulus))
    g = np.gcd(step, modulus)
    mode = np.bincount((ri * width + rows).ravel(), minlength=r * width).reshape(r, width).argmax(axis=1)
    start = np.mod(mode, modulus)
    m, s, st, gg = modulus[:, None], step[:, None], start[:, None], np.maximum(g, 1)[:, None]
    on_orbit = a < m
    if (g > 1).any():  # an orbit of every g-th value (a gcd of 1 takes every value)
        on_orbit &= np.mod(a - st, gg) == 0
    succ = a + s  # s in [0, m): below 2m wherever a is on the orbit; the modulo as one subtraction
    succ -= m * (succ >= m)
    normal = (on_orbit & (b == succ)).sum(axis=1)
    return np.where(moved & (step != 0), normal, -1)


def _successors_may_win(rows: I64, normal: npt.NDArray[np.bool_],
                        width: int) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Per row: whether any pattern, and whether a :func:`_sequence_pattern` candidate, may explain more steps.

    Every pattern explains the steps ``a -> b`` with ``b`` its successor of ``a`` (:meth:`Steps.of`),
    so another pattern gains over the current one only at values ``a`` whose deviating step
    ``a -> w`` is seen more often than ``a -> successor``: where no value has one, no candidate
    can win (first array). A sequence links each value to one successor seen at least twice, so
    it may win only if such a deviating, moving step is seen at least twice (second array).
    """
    r = rows.shape[0]
    a, b = rows[:, :-1], rows[:, 1:]
    ri, ci = np.nonzero(~normal)
    none = np.zeros(r, bool)
    if not ri.size:
        return none, none.copy()
    av, bv = a[ri, ci], b[ri, ci]
    pairs, first, counts = np.unique((ri * width + av) * width + bv, return_index=True, return_counts=True)
    src = pairs // width  # row * width + value
    own = np.bincount((np.arange(r, dtype=np.int64)[:, None] * width + a)[normal], minlength=r * width)
    more = counts > own[src]  # the pattern's successor of that value, per row
    rows_of = src // width
    any_win, seq_win = none, none.copy()
    any_win[rows_of[more]] = True
    seq_win[rows_of[more & (counts >= 2) & (av[first] != bv[first])]] = True
    return any_win, seq_win


class CounterTrack:
    """Streamed values of one counter on one bus -> :class:`CounterGaps` (memory: what one chunk brings).

    The pattern is learned window by window (:meth:`_flush`) where the counter starts and where
    it changes; every other window is judged in bulk against the current pattern
    (:meth:`_verify_in_bulk`), with the same result.
    """

    def __init__(self, message: str, signal: str, channel: int, length: int, hint: int) -> None:
        self.width = 1 << length
        self.hint = hint
        self._pv: list[I64] = []  # fed, not yet joined to the buffer
        self._pt: list[I64] = []
        self._bv: I64 = np.empty(0, np.int64)  # buffer: values from ``_off`` on are not judged yet
        self._bt: I64 = np.empty(0, np.int64)
        self._off = 0
        self._n = 0  # values not judged yet
        self._anchor: tuple[int, int] | None = None  # last value and time of the previous window
        self._pattern: Pattern | None = None
        self._by_pattern: dict[str, tuple[Pattern, int]] = {}  # description -> (pattern, steps checked)
        self._normal = 0
        self._plan: _Plan | None = None
        self.result = CounterGaps(message, signal, channel, 0, hint, 0, 0, 0, None)

    def feed(self, values: npt.NDArray[np.floating], t_ns: I64) -> None:
        """Append finite counter values (raw integers as floats) and their times (ns)."""
        if not values.size:
            return
        self._pv.append(values.astype(np.int64))
        self._pt.append(np.asarray(t_ns, np.int64))
        self._n += values.size
        self.result.frames += int(values.size)
        while self._n >= WINDOW:
            if not self._verify_in_bulk():
                self._flush(WINDOW)

    def _join(self) -> None:
        """Move what was fed into the buffer (one array from ``_off``)."""
        if self._pv:
            if self._off >= self._bv.size and len(self._pv) == 1:  # nothing left over: no copy
                self._bv, self._bt = self._pv[0], self._pt[0]
            else:
                self._bv = np.concatenate([self._bv[self._off:], *self._pv])
                self._bt = np.concatenate([self._bt[self._off:], *self._pt])
            self._off = 0
            self._pv, self._pt = [], []

    def _verify_in_bulk(self) -> bool:
        """Count, all at once, the whole windows that window-by-window learning would count under the current pattern.

        Such a window keeps the current pattern because no candidate of :func:`best_pattern`
        explains more of its steps (the step candidate is built and scored for each window
        in one pass; the sequence and constant candidates are bounded by the transition
        counts), the pattern explains ``MIN_FIT`` of them, its last step is no gap and it
        holds no run of ``RUN`` gaps. Counting those windows together gives the same
        result. Returns False when the first buffered window is not one of them.
        """
        if self._pattern is None or self._anchor is None:
            return False
        self._join()
        plan = self._plan
        if (plan is None or plan.pattern is not self._pattern or plan.base is not self._bv
                or (self._off - plan.off) % WINDOW or self._off >= plan.off + plan.windows * WINDOW):
            plan = self._plan = self._make_plan()
        w0 = (self._off - plan.off) // WINDOW
        bad = np.flatnonzero(~plan.ok[w0:])
        w1 = w0 + int(bad[0]) if bad.size else plan.windows
        if w1 == w0:
            return False
        r = self.result
        r.gaps += int(plan.gaps[w1] - plan.gaps[w0])
        r.missed += int(plan.missed[w1] - plan.missed[w0])
        r.repeats += int(plan.repeats[w1] - plan.repeats[w0])
        if r.first_gap_s is None:
            first = plan.first_gap[w0:w1]
            hit = first[first >= 0]
            if hit.size:
                r.first_gap_s = float(self._bt[int(hit[0])]) / 1e9
        self._normal += int(plan.normal[w1] - plan.normal[w0])
        done = (w1 - w0) * WINDOW
        key = self._pattern.describe()
        self._by_pattern[key] = (self._pattern, self._by_pattern[key][1] + done)
        self._off += done
        self._n -= done
        self._anchor = (int(self._bv[self._off - 1]), int(self._bt[self._off - 1]))
        return True

    def _make_plan(self) -> _Plan:
        """Judge every whole window of the buffer against the current pattern (see :class:`_Plan`)."""
        pattern, anchor = self._pattern, self._anchor
        assert pattern is not None and anchor is not None
        m = (self._bv.size - self._off) // WINDOW
        vals = self._bv[self._off:self._off + m * WINDOW]
        flat = np.empty(vals.size, bool)  # each step follows the pattern (what Steps.of calls normal)
        flat[0] = vals[0] == pattern.succ[anchor[0]]
        np.equal(vals[1:], pattern.succ[vals[:-1]], out=flat[1:])
        normal = flat.reshape(m, WINDOW)
        n_normal = WINDOW - np.bincount(np.flatnonzero(~flat) // WINDOW, minlength=m)  # deviations are few
        ok = n_normal == WINDOW  # perfect: best_pattern keeps the pattern at once
        n_gaps, n_missed, n_repeats = np.zeros(m, np.int64), np.zeros(m, np.int64), np.zeros(m, np.int64)
        first_gap = np.full(m, -1, np.int64)
        bad = np.flatnonzero(~ok)
        if bad.size:  # the deviating windows only: what Steps.of counts, then whether the pattern stays
            seq = np.concatenate(([anchor[0]], vals))
            rows = seq[(bad * WINDOW)[:, None] + np.arange(WINDOW + 1)]
            a, b, nb = rows[:, :-1], rows[:, 1:], normal[bad]
            p = pattern.pos[rows]
            size = pattern.cycle.size
            k = p[:, 1:] - p[:, :-1]  # positions along the cycle, modulo its size: one addition, no division
            k += size * (k < 0)
            k[(p[:, 1:] < 0) | (p[:, :-1] < 0)] = -1
            repeat = (a == b) & ~nb
            gap = ~nb & ~repeat
            n_gaps[bad], n_repeats[bad] = gap.sum(axis=1), repeat.sum(axis=1)
            n_missed[bad] = np.where(gap & (k > 1), k - 1, 0).sum(axis=1)
            first_gap[bad] = np.where(n_gaps[bad] > 0, self._off + bad * WINDOW + gap.argmax(axis=1), -1)
            if size > 1:  # a constant pattern that deviates: window by window
                maybe = np.flatnonzero((n_normal[bad] / WINDOW >= MIN_FIT) & ~gap[:, -1] & ~_runs_at_least(gap, RUN))
                if maybe.size:
                    any_win, beaten = _successors_may_win(rows[maybe], nb[maybe], self.width)
                    step = np.flatnonzero(any_win & ~beaten)  # the step candidate is built only where it may win
                    if step.size:
                        beaten[step] = (_step_candidate_normal(rows[maybe[step]], self.width, self.hint)
                                        > n_normal[bad[maybe[step]]])
                    ok[bad[maybe[~beaten]]] = True
        totals = np.zeros((4, m + 1), np.int64)  # one leading zero per row
        np.cumsum(np.stack((n_normal, n_gaps, n_missed, n_repeats)), axis=1, out=totals[:, 1:])
        normal_c, gaps_c, missed_c, repeats_c = totals
        return _Plan(pattern, self._bv, self._off, ok, normal_c, gaps_c, missed_c, repeats_c, first_gap)

    def finish(self) -> CounterGaps:
        """Judge what is still buffered and summarise (call once, at the end)."""
        self._join()
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
        """Learn and judge the next ``n`` buffered values window by window (the reference algorithm)."""
        self._join()
        v, t = self._bv[self._off:], self._bt[self._off:]
        seq, ts = v[:n], t[:n]
        if self._anchor is not None:
            seq, ts = np.r_[self._anchor[0], seq], np.r_[self._anchor[1], ts]
        carry = self._examine(seq, ts, final) if seq.size >= 2 else 0
        if carry >= n:  # cannot happen (a carry is at most a tenth of a fitting piece); never loop
            carry = self._examine(seq, ts, True)
        done = n - carry
        self._off += done
        self._n -= done
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
