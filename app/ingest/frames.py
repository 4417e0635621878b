"""Columnar CAN frames: the one format every reader produces and the decoder consumes.

A log is read as a stream of :class:`FrameChunk` objects, each holding up to
``chunk_frames`` frames as parallel numpy columns. Memory is bounded by the chunk
size, not by the log size.

Columns (all length ``n``)::

    t_ns     int64   ns since the start of the measurement (first frame may be > 0)
    channel  int16   bus channel as the log numbers it (0-based; -1 when unknown)
    arb_id   uint32  arbitration ID without flag bits (11 or 29 bit)
    flags    uint8   bit set of FrameFlag
    dlc      uint8   number of data bytes (python-can's ``Message.dlc`` meaning; 0..64)
    data     uint8   (n, width) payload, zero padded; width is 8 for classic-only chunks, 64 with FD

The log-level metadata (:class:`LogMeta`) carries the absolute start time and which
clock it came from, because formats disagree (BLF header SYSTEMTIME is local time,
ASC ``date`` header is local time with ms precision, CSV exports use an unknown epoch).
Problems found while reading are collected in an :class:`IngestReport`; a strict
reader raises instead of collecting.
"""

from __future__ import annotations

import enum
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from datetime import datetime
from typing import Any

import numpy as np
import numpy.typing as npt


class FrameFlag(enum.IntFlag):
    EXTENDED = 1
    FD = 2
    ERROR = 4
    REMOTE = 8
    BRS = 16
    ESI = 32
    TX = 64


EXTENDED_KEY = 0x8000_0000  # frame key bit for extended IDs, as cantools uses internally
NO_MESSAGE_KEY = 1 << 30  # frame key bit of error and remote frames (they carry no message)
SMALL_CHUNK = 64  # chunks up to this many frames take the per-call-cheap paths (a live batch)
_FLAGS = np.arange(256)  # every flags byte (numpy: 256 enum operations would cost a millisecond of start-up)
_KEY_BITS = (np.where(_FLAGS & FrameFlag.EXTENDED, EXTENDED_KEY, 0)
             | np.where(_FLAGS & (FrameFlag.ERROR | FrameFlag.REMOTE), NO_MESSAGE_KEY, 0)).astype(np.uint32)


@dataclass(frozen=True, slots=True)
class FrameChunk:
    t_ns: npt.NDArray[np.int64]
    channel: npt.NDArray[np.int16]
    arb_id: npt.NDArray[np.uint32]
    flags: npt.NDArray[np.uint8]
    dlc: npt.NDArray[np.uint8]
    data: npt.NDArray[np.uint8]

    def __post_init__(self) -> None:
        n = len(self.t_ns)
        for name in ("channel", "arb_id", "flags", "dlc"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"FrameChunk column {name} has {len(getattr(self, name))} rows, t_ns has {n}")
        if self.data.ndim != 2 or self.data.shape[0] != n:
            raise ValueError(f"FrameChunk data must be (n, width), got {self.data.shape} for n={n}")

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def width(self) -> int:
        return int(self.data.shape[1])

    def select(self, mask: npt.NDArray[np.bool_]) -> FrameChunk:
        return FrameChunk(
            self.t_ns[mask], self.channel[mask], self.arb_id[mask],
            self.flags[mask], self.dlc[mask], self.data[mask],
        )

    @staticmethod
    def empty(width: int = 8) -> FrameChunk:
        return FrameChunk(
            np.empty(0, np.int64), np.empty(0, np.int16), np.empty(0, np.uint32),
            np.empty(0, np.uint8), np.empty(0, np.uint8), np.empty((0, width), np.uint8),
        )

    @staticmethod
    def concat(chunks: Iterable[FrameChunk]) -> FrameChunk:
        """Concatenate chunks, widening payloads to the widest chunk."""
        parts = [c for c in chunks if len(c)]
        if not parts:
            return FrameChunk.empty()
        width = max(c.width for c in parts)
        data = np.zeros((sum(len(c) for c in parts), width), np.uint8)
        row = 0
        for c in parts:
            data[row:row + len(c), : c.width] = c.data
            row += len(c)
        return FrameChunk(
            np.concatenate([c.t_ns for c in parts]),
            np.concatenate([c.channel for c in parts]),
            np.concatenate([c.arb_id for c in parts]),
            np.concatenate([c.flags for c in parts]),
            np.concatenate([c.dlc for c in parts]),
            data,
        )


@dataclass(slots=True)
class ReadIssue:
    """One problem found while reading: where (byte offset or line), what, how many frames lost."""

    # kind: "truncated", "bad_object_size", "corrupt_zlib", "bad_line", "non_hex", "short_data", "time_backwards"...
    kind: str
    message: str
    offset: int | None = None  # byte offset in the file (binary formats)
    line: int | None = None  # 1-based line number (text formats)
    count: int = 1  # occurrences merged into this entry
    frames_lost: int | None = None  # frames known or estimated lost, None if unknown
    bytes_lost: int | None = None  # bytes of the log skipped or unreadable (binary formats), None if unknown


@dataclass(slots=True)
class IngestReport:
    """What a reader saw: counts and every skipped or corrupt region."""

    frames: int = 0
    issues: list[ReadIssue] = field(default_factory=list)
    max_issues: int = 1000  # beyond this, issues of the same kind are merged into counts

    def add(self, issue: ReadIssue) -> None:
        if len(self.issues) < self.max_issues:
            self.issues.append(issue)
            return
        for existing in reversed(self.issues):
            if existing.kind == issue.kind:
                existing.count += issue.count
                return
        self.issues.append(issue)

    @property
    def ok(self) -> bool:
        return not self.issues


@dataclass(slots=True)
class LogMeta:
    """Log-level facts: the format, the absolute start time and the clock it came from."""

    format: str  # a name of app.log_formats.LOG_FORMATS: "blf", "asc", "candump", ..., "described"
    start_time: datetime | None = None  # absolute time of t_ns == 0
    start_clock: str = "unknown"  # e.g. "blf_header_local", "asc_date_header_local", "epoch_utc", "unknown"
    channels: dict[int, str] = field(default_factory=dict)  # channel number -> name if the log says
    extra: dict[str, str] = field(default_factory=dict)


def iter_frames_py(chunks: Iterable[FrameChunk]) -> Iterator[tuple[int, int, int, int, bytes]]:
    """Frames as ``(t_ns, channel, arb_id, flags, payload)`` tuples, for tests and small tools."""
    for c in chunks:
        for i in range(len(c)):
            yield (int(c.t_ns[i]), int(c.channel[i]), int(c.arb_id[i]), int(c.flags[i]),
                   bytes(c.data[i, : c.dlc[i]]))


MASK_GROUPS = 24  # up to this many distinct keys, rows are grouped by one comparison per key (no sort)


def distinct(values: npt.NDArray[np.generic]) -> list[Any]:
    """The distinct values, ascending, as Python numbers (a sort; ``np.unique`` would load ``numpy.ma``)."""
    if not values.size:
        return []
    lo, hi = values.min(), values.max()
    if lo == hi:
        return [lo.item()]
    ordered = np.sort(values)
    return ordered[np.concatenate(([True], ordered[1:] != ordered[:-1]))].tolist()


FrameGroups = list[tuple[int, npt.NDArray[np.intp]]]


def frame_groups(chunk: FrameChunk) -> FrameGroups:
    """Rows of each frame key of ``chunk``: ID | extended << 31 | (error or remote) << 30, rows in order.

    Computed once per chunk and handed to the decoder and the bus statistics, which both work
    per ID.
    """
    key = chunk.arb_id | _KEY_BITS[chunk.flags]
    if key.size > SMALL_CHUNK:
        return group_rows(key)
    rows: dict[int, list[int]] = {}  # a live batch: grouping in Python costs less than the array calls
    for i, k in enumerate(key.tolist()):
        rows.setdefault(k, []).append(i)
    return [(k, np.array(r, np.intp)) for k, r in rows.items()]


def group_rows(key: npt.NDArray[np.integer]) -> list[tuple[int, npt.NDArray[np.intp]]]:
    """Rows of each distinct ``key`` value, in row order, keys ascending.

    A bus log carries few distinct IDs per chunk as a rule, and one comparison pass per key
    costs less than a stable sort of the chunk; many distinct keys take the sort.
    """
    if not key.size:
        return []
    ordered = np.sort(key)  # np.unique's hashing is ten times slower on a chunk of few IDs
    uniq = ordered[np.concatenate(([True], ordered[1:] != ordered[:-1]))]
    if uniq.size == 1:
        return [(int(uniq[0]), np.arange(key.size))]
    if uniq.size <= MASK_GROUPS:
        return [(k, np.flatnonzero(key == k)) for k in uniq.tolist()]
    order = np.argsort(key, kind="stable")  # stable: rows of one key stay in row order
    sorted_keys = key[order]
    cuts = (np.flatnonzero(sorted_keys[1:] != sorted_keys[:-1]) + 1).tolist()
    starts, stops = [0, *cuts], [*cuts, key.size]
    return [(k, order[a:b]) for a, b, k in zip(starts, stops, sorted_keys[starts].tolist(), strict=True)]
