"""Replay a log onto a CAN bus with its original timing.

Pacing uses absolute deadlines: frame *i* is due at ``start + (t_i - t_first) / rate``
on the monotonic clock, so a late frame (a slow send, a descheduled thread) never
shifts the frames after it, unlike a loop that sleeps the inter-frame gap. Waiting is
a sleep to just before the deadline followed by a short spin, because a plain sleep
overshoots by 50-100 µs on Linux and far more when the machine is busy.

Reading the log happens in a prefetch thread (a bounded queue of chunks), so decoding
the next chunk of a large log never stalls the pacing loop. While replaying, the
interpreter's GIL switch interval is lowered (5 ms -> 0.25 ms): otherwise the pacing
thread, woken at its deadline, can wait up to 5 ms for the reader thread to yield.

The pacing error of every frame (actual send time minus deadline) goes into a
fixed-size histogram with 10 µs bins, so percentiles come at constant memory for
replays of any length.
"""

from __future__ import annotations

import contextlib
import os
import queue
import sys
import threading
import time
from collections.abc import Callable, Collection, Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np

from app.errors import InputError
from app.ingest.frames import FrameChunk
from app.live.bus import BusLink
from app.live.convert import chunk_to_messages

SPIN_NS = 300_000  # sleep until this close to the deadline, then spin
BIN_NS = 10_000  # pacing histogram resolution
N_BINS = 20_000  # 10 µs x 20 000 = 200 ms; later frames land in the last bin
SWITCH_INTERVAL_S = 0.00025
# Speed factors outside this range are no replay: below it a 10 ms gap waits hours and deadlines leave
# the clock's range; above it every frame is late anyway (send as fast as the bus takes them).
RATE_MIN, RATE_MAX = 1e-3, 1e3

ChunkSource = Callable[[], Iterable[FrameChunk]]


class PacingHistogram:
    """Pacing errors (ns, >= 0 after clipping) in 10 µs bins; constant memory."""

    def __init__(self) -> None:
        self.counts = np.zeros(N_BINS, np.int64)
        self.n = 0
        self.early = 0  # sent before the deadline (should stay 0)
        self.max_ns = 0

    def add(self, err_ns: int) -> None:
        if err_ns < 0:
            self.early += 1
            err_ns = 0
        self.counts[min(err_ns // BIN_NS, N_BINS - 1)] += 1
        self.n += 1
        self.max_ns = max(self.max_ns, err_ns)

    def percentile_ms(self, q: float) -> float:
        """Upper edge of the bin holding the ``q``-th percentile, in ms (0 when empty)."""
        if self.n == 0:
            return 0.0
        rank = int(np.ceil(q / 100.0 * self.n))
        idx = int(np.searchsorted(np.cumsum(self.counts), max(rank, 1)))
        return (idx + 1) * BIN_NS / 1e6


@dataclass
class ReplayStats:
    """Progress and, at the end, the summary of a replay."""

    frames_sent: int = 0
    frames_skipped: int = 0  # filtered out by --ids / channel
    send_failures: int = 0  # the bus refused the frame or was away
    loops_done: int = 0
    log_time_s: float = 0.0  # position in the log (s since its first frame)
    wall_s: float = 0.0
    stopped_early: bool = False
    realtime: bool = False  # the pacing thread got a real-time scheduling priority
    pacing: PacingHistogram = field(default_factory=PacingHistogram)

    def summary(self) -> dict[str, float | int | bool]:
        return {
            "frames_sent": self.frames_sent,
            "frames_skipped": self.frames_skipped,
            "send_failures": self.send_failures,
            "loops_done": self.loops_done,
            "log_time_s": round(self.log_time_s, 6),
            "wall_s": round(self.wall_s, 6),
            "stopped_early": self.stopped_early,
            "realtime": self.realtime,
            "pacing_p50_ms": self.pacing.percentile_ms(50),
            "pacing_p99_ms": self.pacing.percentile_ms(99),
            "pacing_max_ms": round(self.pacing.max_ns / 1e6, 3),
        }


def check_rate(rate: float) -> float:
    """``rate`` if it lies in [RATE_MIN, RATE_MAX]; else :class:`InputError` naming the bounds."""
    if not RATE_MIN <= rate <= RATE_MAX:  # also refuses NaN
        raise InputError(f"--rate must be between {RATE_MIN:g} and {RATE_MAX:g} (a speed factor), got {rate:g}")
    return rate


def parse_ids(text: str | None) -> frozenset[int] | None:
    """``"0x108,0x118 264"`` -> ``{0x108, 0x118, 264}`` (``0x`` for hex, plain digits decimal)."""
    if not text:
        return None
    out = set()
    for tok in text.replace(",", " ").split():
        try:
            value = int(tok, 0)
        except ValueError as exc:
            raise InputError(f"--ids: {tok!r} is not an ID (write hex as 0x108, decimal as 264)") from exc
        if not 0 <= value <= 0x1FFFFFFF:
            raise InputError(f"--ids: {tok} is outside the 29-bit CAN ID range")
        out.add(value)
    return frozenset(out)


def _filtered(chunks: Iterable[FrameChunk], ids: Collection[int] | None,
              channels: Collection[int] | None, stats: ReplayStats) -> Iterator[FrameChunk]:
    id_arr = np.fromiter(ids, np.uint32) if ids else None
    ch_arr = np.fromiter(channels, np.int16) if channels else None
    for c in chunks:
        if id_arr is None and ch_arr is None:
            yield c
            continue
        keep = np.ones(len(c), bool)
        if id_arr is not None:
            keep &= np.isin(c.arb_id, id_arr)
        if ch_arr is not None:
            keep &= np.isin(c.channel, ch_arr)
        stats.frames_skipped += int((~keep).sum())
        yield c.select(keep)


class Replayer:
    """Send the frames of a log onto a bus at their original pace.

    Parameters
    ----------
    link : BusLink
        An opened bus link; failed sends are counted and the link reconnects.
    source : callable returning an iterable of FrameChunk
        Called once per pass (again for each ``loop``), e.g. ``lambda: open_log(p).chunks()``.
    rate : float
        Speed factor: 2.0 replays twice as fast, 0.5 at half speed.
    loop : bool
        Start again from the beginning at the end, until stopped.
    ids, channels : collections of int, optional
        Replay only these arbitration IDs / log channels.
    progress : callable, optional
        Called with the live :class:`ReplayStats` about every ``progress_every_s``.
    """

    def __init__(self, link: BusLink, source: ChunkSource, *, rate: float = 1.0, loop: bool = False,
                 ids: Collection[int] | None = None, channels: Collection[int] | None = None,
                 progress: Callable[[ReplayStats], None] | None = None, progress_every_s: float = 0.5,
                 lead_s: float = 0.05, realtime: bool = True) -> None:
        check_rate(rate)
        self.link = link
        self.source = source
        self.rate = rate
        self.loop = loop
        self.ids = ids
        self.channels = channels
        self.progress = progress
        self.progress_every_ns = int(progress_every_s * 1e9)
        self.lead_ns = int(lead_s * 1e9)
        self.realtime = realtime
        self.stats = ReplayStats()
        self._stop = threading.Event()

    def stop(self) -> None:
        """Ask :meth:`run` to return after the current frame (safe from a signal handler)."""
        self._stop.set()

    def _wait_until(self, deadline_ns: int) -> bool:
        while True:
            remaining = deadline_ns - time.perf_counter_ns()
            if remaining <= 0:
                return True
            if remaining > SPIN_NS:
                if self._stop.wait((remaining - SPIN_NS) / 1e9):
                    return False
            elif self._stop.is_set():
                return False

    def _prefetch(self, q: queue.Queue[FrameChunk | BaseException | None]) -> None:
        try:
            while True:
                for c in _filtered(self.source(), self.ids, self.channels, self.stats):
                    if len(c):
                        while not self._stop.is_set():
                            try:
                                q.put(c, timeout=0.1)
                                break
                            except queue.Full:
                                continue
                    if self._stop.is_set():
                        return
                q.put(_END_OF_PASS)
                if not self.loop:
                    return
        except BaseException as exc:
            q.put(exc)
        finally:
            q.put(None)

    def run(self) -> ReplayStats:
        """Replay until the log ends (or forever with ``loop``) or :meth:`stop` is called."""
        stats = self.stats
        if self.realtime:
            stats.realtime = _enter_realtime()
        q: queue.Queue[FrameChunk | BaseException | None] = queue.Queue(maxsize=4)
        reader = threading.Thread(target=self._prefetch, args=(q,), name="replay-prefetch", daemon=True)
        old_switch = sys.getswitchinterval()
        sys.setswitchinterval(min(old_switch, SWITCH_INTERVAL_S))
        reader.start()
        start_ns = time.perf_counter_ns() + self.lead_ns
        next_progress = start_ns + self.progress_every_ns
        first_t: int | None = None
        last_t = 0
        offset_ns = 0  # log time added per completed loop
        try:
            while True:
                item = q.get()
                if item is None:
                    break
                if isinstance(item, BaseException):
                    raise item
                if item is _END_OF_PASS:
                    stats.loops_done += 1
                    if first_t is not None and self.loop:
                        span = last_t - first_t
                        gap = span // max(stats.frames_sent, 1) or 1_000_000
                        offset_ns += span + gap
                        first_t = None
                    continue
                if first_t is None:
                    first_t = int(item.t_ns[0]) - offset_ns
                for i, msg in enumerate(chunk_to_messages(item)):
                    t = int(item.t_ns[i])
                    last_t = t
                    log_ns = t - first_t
                    deadline = start_ns + int(log_ns / self.rate)
                    if not self._wait_until(deadline):
                        stats.stopped_early = True
                        return stats
                    now = time.perf_counter_ns()
                    stats.pacing.add(now - deadline)
                    if self.link.send(msg):
                        stats.frames_sent += 1
                    else:
                        stats.send_failures += 1
                    stats.log_time_s = log_ns / 1e9
                    if self.progress is not None and now >= next_progress:
                        stats.wall_s = (now - start_ns) / 1e9
                        self.progress(stats)
                        next_progress = now + self.progress_every_ns
                if self._stop.is_set():
                    stats.stopped_early = True
                    return stats
            return stats
        finally:
            self._stop.set()
            stats.wall_s = max(0.0, (time.perf_counter_ns() - start_ns) / 1e9)
            reader.join(2.0)
            sys.setswitchinterval(old_switch)
            if stats.realtime:
                _leave_realtime()


_END_OF_PASS = FrameChunk.empty()


def _enter_realtime(priority: int = 10) -> bool:
    """Give the calling (pacing) thread round-robin real-time priority where the OS allows it.

    On a busy machine a normal thread woken at its deadline can wait a whole scheduler slice
    (several ms) for a CPU; a real-time thread preempts normal ones. Linux caps real-time CPU use
    (``sched_rt_runtime_us``), and the thread sleeps between frames, so this cannot starve the
    machine. Without the privilege (CAP_SYS_NICE or an rtprio limit) replay runs unprivileged.
    """
    setter = getattr(os, "sched_setscheduler", None)
    policy = getattr(os, "SCHED_RR", None)
    if setter is None or policy is None:
        return False
    try:
        setter(0, policy, os.sched_param(priority))  # pid 0 = the calling thread on Linux
    except OSError:
        return False
    return True


def _leave_realtime() -> None:
    setter = getattr(os, "sched_setscheduler", None)
    if setter is not None:
        with contextlib.suppress(OSError):
            setter(0, os.SCHED_OTHER, os.sched_param(0))

