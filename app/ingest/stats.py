"""Bus statistics while streaming a log: per-ID counts, periods and jitter, counter gaps, time anomalies.

Everything is accumulated chunk by chunk (memory independent of log length) and ends in a
:class:`DecodeReport`, a plain dataclass tree the service stores as JSON and the CLI prints.

* **Per-ID periods**: for each (bus channel, ID, extended flag) the mean and standard deviation
  (jitter) of the time between consecutive frames, with the smallest and largest gap, the
  median and 95th percentile gap and a ``bursty`` flag (:mod:`app.signals.sampling`). The
  percentiles come from a log-spaced histogram of the gaps (5000 bins per decade, each bin
  remembering the mean of its gaps), so memory does not grow with the log; they are within
  0.05 % of the exact value, and exact when the gaps in the median's bin are all equal
  (a logger's millisecond stamps).
* **Counter gaps**: alive/rolling counters (unsigned, unscaled, 2..8 bits, named like
  ``alive``, ``counter``, ``cnt``, ``rolling``, ``seq``). Each counter's pattern (step and
  modulus, or the order of its values, or constant) is learned from the data
  (:mod:`app.ingest.counters`); a gap is a step that deviates from it.
* **Timestamp anomalies**, per bus channel in file order: time going backwards, and jumps
  (no frame on the channel for more than ``jump_s``).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from cantools.database.can import Database as CanDatabase
from cantools.database.can import Signal as CanSignal

from app.ingest.counters import CounterGaps, CounterTrack, dbc_modulus
from app.ingest.database import Repair
from app.ingest.decode import EXTENDED_KEY, DecodedMessage, VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag, FrameGroups, ReadIssue, distinct, frame_groups, group_rows
from app.ingest.j1939 import database_is_j1939, j1939_messages, pgn
from app.signals.sampling import Spacing, burst_reason

_COUNTER_NAME = re.compile(r"(alive|counter|cntr|cnt|rolling|rlc|seq(uence)?)(_?\d+)?$|^(alive|counter|cnt|rc)",
                           re.IGNORECASE)
MAX_LISTED = 50  # anomalies listed individually; the rest are counted


@dataclass(slots=True)
class IdStats:
    channel: int
    arb_id: int
    extended: bool
    message: str | None  # database message name; None for IDs the database does not know
    count: int
    period_ms: float | None  # mean time between frames
    jitter_ms: float | None  # standard deviation of the time between frames
    min_gap_ms: float | None
    max_gap_ms: float | None
    cycle_ms: float | None = None  # what the database says
    median_gap_ms: float | None = None
    p95_gap_ms: float | None = None
    bursty: bool = False  # median far below the mean, or gaps of several means (see app.signals.sampling)
    bursty_reason: str = ""


@dataclass(slots=True)
class TimestampAnomaly:
    kind: str  # "backwards" or "jump"
    channel: int
    frame: int  # 0-based frame index in the log
    t_s: float
    dt_s: float


@dataclass(slots=True)
class DecodeReport:
    """What decoding a log found, for the service and the ``decode`` command."""

    source: str = ""
    format: str = ""
    database: str = ""
    frames_read: int = 0
    frames_decoded: int = 0
    frames_unknown_id: int = 0
    error_frames: int = 0
    remote_frames: int = 0
    duration_s: float = 0.0
    ids: list[IdStats] = field(default_factory=list)
    decode_errors: dict[str, dict[str, int]] = field(default_factory=dict)
    counter_gaps: list[CounterGaps] = field(default_factory=list)
    timestamp_anomalies: list[TimestampAnomaly] = field(default_factory=list)
    anomaly_counts: dict[str, int] = field(default_factory=dict)
    reader_issues: list[ReadIssue] = field(default_factory=list)
    database_repairs: list[Repair] = field(default_factory=list)
    database_notes: list[Repair] = field(default_factory=list)  # cantools' loading warnings (duplicate IDs...)
    channels: dict[str, int] = field(default_factory=dict)  # canonical channel -> samples
    # frames whose ID is a database message's but with the other ID type (11 vs 29 bit): not decoded
    id_type_mismatch: dict[str, int] = field(default_factory=dict)
    sampling: dict[str, Spacing] = field(default_factory=dict)  # canonical channel -> spacing of its samples
    unknown_hint: str = ""  # why most frames are of unknown IDs, when they are


def counter_modulus(sig: CanSignal) -> int | None:
    """The DBC's counting range of an alive counter signal (a hint only), or None when ``sig`` is not one."""
    if (sig.is_float or sig.is_signed or not 2 <= sig.length <= 8 or sig.scale != 1 or sig.offset != 0
            or sig.is_multiplexer or not _COUNTER_NAME.search(sig.name)):
        return None
    return dbc_modulus(sig)


_EXTENDED_BIT = np.where(np.arange(256) & FrameFlag.EXTENDED, EXTENDED_KEY, 0).astype(np.uint32)  # by flags byte
MANTISSA_BITS = 12  # bin width 2**-12 of the gap (0.012-0.024 %): 1000 and 1001 ms fall into different bins
_BIN_SHIFT = 52 - MANTISSA_BITS


def gap_bins(dt_ns: np.ndarray) -> np.ndarray:
    """The histogram bin of each gap: its float's exponent and leading mantissa bits (0: gaps of zero or less).

    A positive float64's bit pattern read as an integer grows with its value, so dropping the low
    mantissa bits bins the gaps on a log-like scale with no logarithm: one shift and one clamp.
    """
    bins = np.ascontiguousarray(dt_ns, np.float64).view(np.int64) >> _BIN_SHIFT
    return np.maximum(bins, 0, out=bins)  # negative floats read as negative integers


class GapHistogram:
    """Gaps (ns) in log-like bins (:func:`gap_bins`), each with its count and sum; percentiles without keeping the gaps.

    Each :meth:`add` keeps its chunk's bins as arrays; they are merged (counts and sums added
    per bin, in the order added) when a quantile is asked or many chunks wait, so a jittery
    message's thousands of bins cost no Python loop per chunk.
    """

    __slots__ = ("_counts", "_keys", "_parts", "_sums")

    _MERGE_AFTER = 64  # pending chunks before a merge (bounds memory on long logs)

    def __init__(self) -> None:
        self._keys: np.ndarray = np.empty(0, np.int64)  # bin (0: zero or negative gaps), ascending
        self._counts: np.ndarray = np.empty(0, np.float64)
        self._sums: np.ndarray = np.empty(0, np.float64)
        self._parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []

    def add(self, dt_ns: np.ndarray, lo_hi: tuple[float, float] | None = None) -> None:
        """Count the gaps ``dt_ns``; ``lo_hi``: their smallest and largest one when the caller has them."""
        if not dt_ns.size:
            return
        b = gap_bins(dt_ns)
        lo_dt, hi_dt = (float(dt_ns.min()), float(dt_ns.max())) if lo_hi is None else lo_hi
        lo, hi = (int(x) for x in gap_bins(np.array([lo_dt, hi_dt])))  # the bins are monotonic in the gap
        band = 4 * b.size + 4096  # bins counted densely from the smallest gap up (periodic gaps fill a narrow band)
        if lo:
            b -= lo
        if hi - lo < band:
            near, gaps = b, dt_ns
            far = None
        else:  # a pause or a reset far above the band: those few gaps are sorted, not a sparse band counted
            out = b >= band
            far = np.unique(b[out], return_inverse=True)
            far_sums = np.bincount(far[1], weights=dt_ns[out])
            near, gaps = b[~out], dt_ns[~out]
        counts = np.bincount(near, minlength=hi - lo + 1 if far is None else 0)  # as long as the band's top gap
        sums = np.bincount(near, weights=gaps, minlength=counts.size)
        keys = np.flatnonzero(counts != 0)  # a bool array: twice as fast on a sparse band
        counts, sums = counts[keys], sums[keys]
        if far is not None:
            keys = np.concatenate((keys, far[0]))
            counts = np.concatenate((counts, np.bincount(far[1])))
            sums = np.concatenate((sums, far_sums))
        keys += lo
        self._parts.append((keys, counts.astype(np.float64), sums))
        if len(self._parts) >= self._MERGE_AFTER:
            self._merge()

    def _merge(self) -> None:
        if not self._parts:
            return
        keys = np.concatenate([self._keys, *(k for k, _, _ in self._parts)])
        counts = np.concatenate([self._counts, *(c for _, c, _ in self._parts)])
        sums = np.concatenate([self._sums, *(t for _, _, t in self._parts)])
        self._parts = []
        self._keys, inverse = np.unique(keys, return_inverse=True)
        self._counts = np.bincount(inverse, weights=counts)  # bincount adds in array order: as added
        self._sums = np.bincount(inverse, weights=sums)

    def quantile(self, q: float) -> float | None:
        """The mean of the gaps in the bin that holds the ``q`` quantile (ns); None when empty."""
        self._merge()
        n = float(self._counts.sum())
        if not n:
            return None
        rank = round(q * (n - 1))
        i = int(np.searchsorted(np.cumsum(self._counts), rank, side="right"))
        return float(self._sums[i] / self._counts[i])


def _gaps(seg: npt.NDArray[np.int64], last: int | None) -> npt.NDArray[np.float64]:
    """The gaps (ns, as floats) between the stamps of ``seg``, the first one from ``last`` when given.

    One subtraction into the float array: no prepended copy and no second pass to convert.
    """
    first = 0 if last is None else 1
    dt = np.empty(seg.size - 1 + first, np.float64)
    if first:
        dt[0] = seg[0] - last
    np.subtract(seg[1:], seg[:-1], out=dt[first:], casting="unsafe")
    return dt


class _Run:
    __slots__ = ("count", "hist", "last", "max", "min", "n", "s1", "s2")

    def __init__(self) -> None:
        self.count, self.n = 0, 0
        self.last: int | None = None
        self.s1 = self.s2 = 0.0
        self.min, self.max = np.inf, -np.inf
        self.hist = GapHistogram()


class StatsAccumulator:
    """Feed chunks (and their decoded messages); :meth:`fill` writes the totals into a report."""

    def __init__(self, db: CanDatabase | None = None, *, jump_s: float = 1.0) -> None:
        self.jump_s = jump_s
        self._runs: dict[tuple[int, int], _Run] = {}
        self._last_t: dict[int, int] = {}  # channel -> last t_ns seen
        self._frames = 0
        self._t_first: int | None = None
        self._t_last: int | None = None
        self._error = self._remote = 0
        self._anomalies: list[TimestampAnomaly] = []
        self._anomaly_counts: dict[str, int] = {}
        self._names: dict[int, tuple[str, float | None]] = {}
        self._counters: dict[str, list[tuple[str, int, int]]] = {}  # message -> (signal, bits, DBC modulus)
        self._tracks: dict[tuple[str, str, int], CounterTrack] = {}
        self._decoded = 0
        self._decode_errors: dict[str, dict[str, int]] = {}  # message -> error kind -> frames
        self._j1939 = db is not None and database_is_j1939(db)
        self._by_pgn: dict[int, tuple[str, float | None]] = {}
        self._pgn_anyway: dict[int, str] = {}  # PGN -> message of the extended messages, for the hint
        if db is not None:
            cycles = {m.name: float(m.cycle_time) if m.cycle_time else None for m in db.messages}
            self._by_pgn = {p: (m.name, cycles[m.name]) for p, m in j1939_messages(db).items()}
            self._pgn_anyway = {pgn(m.frame_id): m.name for m in reversed(db.messages) if m.is_extended_frame}
            for msg in db.messages:
                key = msg.frame_id | (EXTENDED_KEY if msg.is_extended_frame else 0)
                self._names[key] = (msg.name, float(msg.cycle_time) if msg.cycle_time else None)
                found = [(s.name, s.length, m) for s in msg.signals if (m := counter_modulus(s)) is not None]
                if found:
                    self._counters[msg.name] = found

    @property
    def frames(self) -> int:
        """Frames seen so far."""
        return self._frames

    def add(self, chunk: FrameChunk, decoder: VectorDecoder) -> dict[str, DecodedMessage]:
        """Count ``chunk``, decode it with ``decoder`` and count what it decoded; returns the decoded messages.

        The frames are grouped by ID once, for the decoder and the statistics.
        """
        groups = frame_groups(chunk) if len(chunk) else None
        self.add_chunk(chunk, groups)
        decoded = decoder.decode(chunk, groups)
        self.add_decoded(decoded)
        return decoded

    def add_chunk(self, chunk: FrameChunk, groups: FrameGroups | None = None) -> None:
        """Count a chunk of frames; ``groups``: its :func:`~app.ingest.frames.frame_groups` when the caller has them."""
        n = len(chunk)
        if n == 0:
            return
        start = self._frames
        self._frames += n
        t = chunk.t_ns
        lo, hi = int(t.min()), int(t.max())
        self._t_first = lo if self._t_first is None else min(self._t_first, lo)
        self._t_last = hi if self._t_last is None else max(self._t_last, hi)
        seen = int(np.bitwise_or.reduce(chunk.flags))  # every flag some frame of the chunk carries
        error = chunk.flags & np.uint8(FrameFlag.ERROR) if seen & FrameFlag.ERROR else None
        errors = 0 if error is None else int(np.count_nonzero(error))
        self._error += errors
        if seen & FrameFlag.REMOTE:
            self._remote += int(np.count_nonzero(chunk.flags & np.uint8(FrameFlag.REMOTE)))
        c_lo, c_hi = int(chunk.channel.min()), int(chunk.channel.max())
        self._timestamps(chunk, start, c_lo, c_hi)
        if groups is None or c_lo != c_hi or seen & (FrameFlag.ERROR | FrameFlag.REMOTE):
            groups = self._groups(chunk, seen, c_lo != c_hi, None if not errors or error is None else error == 0)
        for k, rows in groups:
            run = self._runs.setdefault(((k >> 33) - 1, k & ((1 << 33) - 1)) if c_lo != c_hi else (c_lo, k), _Run())
            seg = t[rows]
            dt = _gaps(seg, run.last)
            run.count += int(rows.size)
            run.last = int(seg[-1])
            if dt.size:
                run.n += dt.size
                run.s1 += float(dt.sum())
                run.s2 += float(np.square(dt).sum())  # not np.dot: BLAS threads cost ms per call on a busy machine
                dt_lo, dt_hi = float(dt.min()), float(dt.max())
                run.min = min(run.min, dt_lo)
                run.max = max(run.max, dt_hi)
                run.hist.add(dt, (dt_lo, dt_hi))

    @staticmethod
    def _groups(chunk: FrameChunk, seen: int, buses: bool, usable: npt.NDArray[np.bool_] | None) -> FrameGroups:
        """Rows per ID (remote frames with their ID's data frames), per bus when ``buses``, of the ``usable`` rows."""
        key: npt.NDArray[np.integer] = chunk.arb_id  # ID | extended << 31
        if seen & FrameFlag.EXTENDED:
            key = key | _EXTENDED_BIT[chunk.flags]
        if buses:  # several buses: the bus goes into the key
            key = (chunk.channel.astype(np.int64) + 1) << 33 | key.astype(np.int64)
        if usable is None:
            return group_rows(key)
        rows = np.flatnonzero(usable)
        return [(k, rows[r]) for k, r in group_rows(key[rows])]

    def _timestamps(self, chunk: FrameChunk, start: int, lo: int, hi: int) -> None:
        """Backward and jumping time stamps, per bus (``lo``, ``hi``: the chunk's smallest and largest bus)."""
        for ch in [lo] if lo == hi else distinct(chunk.channel):
            rows = None if lo == hi else np.flatnonzero(chunk.channel == ch)  # None: every row
            t = chunk.t_ns if rows is None else chunk.t_ns[rows]
            prev = self._last_t.get(ch)
            dt = np.diff(t) if prev is None else np.diff(t, prepend=prev)
            base = 0 if prev is None else 1
            limit = self.jump_s * 1e9
            back, jump = (bool(dt.min() < 0), bool(dt.max() > limit)) if dt.size else (False, False)
            for kind, found in (("backwards", back), ("jump", jump)):
                if not found:  # one reduction instead of a comparison per row
                    continue
                idx = np.flatnonzero(dt < 0 if kind == "backwards" else dt > limit)
                self._anomaly_counts[kind] = self._anomaly_counts.get(kind, 0) + int(idx.size)
                for i in idx[: max(0, MAX_LISTED - len(self._anomalies))].tolist():
                    r = i + 1 - base
                    row = r if rows is None else int(rows[r])
                    self._anomalies.append(TimestampAnomaly(kind, int(ch), start + row,
                                                            float(t[r]) / 1e9, float(dt[i]) / 1e9))
            self._last_t[ch] = int(t[-1])

    def add_decoded(self, decoded: Mapping[str, DecodedMessage]) -> None:
        """Count the decoded frames and their decode errors; feed the alive counters to their trackers (per bus)."""
        for name, dm in decoded.items():
            self._decoded += len(dm)
            for kind, count in dm.errors.items():
                per_kind = self._decode_errors.setdefault(name, {})
                per_kind[kind] = per_kind.get(kind, 0) + count
        for dm in decoded.values():
            base_name = dm.name.split("@", 1)[0]
            for sig, bits, hint in self._counters.get(base_name, []):
                values = dm.signals.get(sig)
                if values is None or not len(dm):
                    continue
                finite = np.isfinite(values)
                buses = distinct(dm.channel)
                for ch in buses:
                    key = (dm.name, sig, int(ch))
                    track = self._tracks.get(key)
                    if track is None:
                        track = self._tracks[key] = CounterTrack(dm.name, sig, int(ch), bits, hint)
                    if len(buses) == 1 and finite.all():  # every row: no copies
                        track.feed(values, dm.t_ns)
                        continue
                    m = (dm.channel == ch) & finite
                    track.feed(values[m], dm.t_ns[m])

    def _unknown_hint(self, report: DecodeReport, unknown_ids: set[int], pgn_hits: dict[str, int]) -> str:
        """Why most frames are of unknown IDs, when they are (empty otherwise)."""
        unknown = report.frames_unknown_id
        usable = report.frames_read - report.error_frames
        if not usable or unknown * 2 <= usable:
            return ""
        share = f"{unknown} of {usable} frames ({100 * unknown / usable:.0f} %) have IDs the database does not define"
        if pgn_hits and not self._j1939:
            top = max(pgn_hits, key=lambda k: pgn_hits[k])
            return (f"{share}; {sum(pgn_hits.values())} of them carry the J1939 PGN of a database message (e.g. "
                    f"{top}) with another priority or source address: the database does not declare J1939 "
                    "(BA_ \"ProtocolType\" \"J1939\"; or VFrameFormat J1939PG), so IDs must match exactly")
        if self._j1939:
            return (f"{share}; the database is J1939, so IDs match by PGN (priority and source address ignored), "
                    f"and none of the {len(unknown_ids)} unknown IDs carries a PGN it defines: another vehicle or "
                    "bus, or the wrong database")
        if report.id_type_mismatch:
            return f"{share}; some carry a database ID with the other ID type (11/29 bit), listed below"
        return (f"{share} ({len(unknown_ids)} distinct IDs): another vehicle or bus, or the wrong database")

    def fill(self, report: DecodeReport) -> DecodeReport:
        """Write the totals into ``report`` (returned for chaining)."""
        report.frames_read = self._frames
        report.frames_decoded = self._decoded
        report.error_frames, report.remote_frames = self._error, self._remote
        if self._t_first is not None and self._t_last is not None:
            report.duration_s = (self._t_last - self._t_first) / 1e9
        unknown = 0
        ids = []
        pgn_hits: dict[str, int] = {}  # unknown frames whose PGN is a database message's
        unknown_ids: set[int] = set()
        for (ch, key), run in sorted(self._runs.items()):
            name, cycle = self._names.get(key, (None, None))
            if name is None and key & EXTENDED_KEY and self._by_pgn:
                name, cycle = self._by_pgn.get(pgn(key & 0x1FFF_FFFF), (None, None))
            if name is None:
                unknown += run.count
                unknown_ids.add(key)
                hit = self._pgn_anyway.get(pgn(key & 0x1FFF_FFFF)) if key & EXTENDED_KEY else None
                if hit is not None:
                    pgn_hits[hit] = pgn_hits.get(hit, 0) + run.count
                other = self._names.get(key ^ EXTENDED_KEY)
                if other is not None:
                    report.id_type_mismatch[other[0]] = report.id_type_mismatch.get(other[0], 0) + run.count
            mean = run.s1 / run.n if run.n else None
            std = float(np.sqrt(max(run.s2 / run.n - mean * mean, 0.0))) if mean is not None else None
            median, p95 = run.hist.quantile(0.5), run.hist.quantile(0.95)
            stat = IdStats(ch, key & 0x1FFF_FFFF, bool(key & EXTENDED_KEY), name, run.count,
                           None if mean is None else mean / 1e6, None if std is None else std / 1e6,
                           None if not run.n else run.min / 1e6, None if not run.n else run.max / 1e6, cycle,
                           None if median is None else median / 1e6, None if p95 is None else p95 / 1e6)
            stat.bursty_reason = burst_reason(run.n, stat.period_ms, stat.median_gap_ms, stat.max_gap_ms)
            stat.bursty = bool(stat.bursty_reason)
            ids.append(stat)
        report.ids = ids
        report.frames_unknown_id = unknown
        report.unknown_hint = self._unknown_hint(report, unknown_ids, pgn_hits)
        gaps = [track.finish() for track in self._tracks.values()]
        self._tracks = {}  # finished: the summary is final
        report.counter_gaps = sorted(gaps, key=lambda g: (-g.missed, g.message, g.signal, g.channel))
        report.timestamp_anomalies = list(self._anomalies)
        report.anomaly_counts = dict(self._anomaly_counts)
        if self._decode_errors:
            report.decode_errors = {k: dict(v) for k, v in self._decode_errors.items() if v}
        return report
