"""What every reader shares: chunk assembly, problem reporting (salvage vs strict), the iteration guard.

A reader subclass parses its header in ``_open`` (so :attr:`BaseReader.meta` is filled as
soon as the reader exists) and yields chunks from ``_iter_chunks``. It reports every
problem through :meth:`BaseReader.problem`, which either records a
:class:`~app.ingest.frames.ReadIssue` (salvage, the default) or raises at once (strict).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from types import TracebackType
from typing import ClassVar

import numpy as np
import numpy.typing as npt

from app.errors import AppError, InputError, LogFormatError, TruncatedLogError
from app.ingest.frames import FrameChunk, FrameFlag, IngestReport, LogMeta, ReadIssue
from app.ingest.readers._source import ByteStream, StreamDamage

MAX_PAYLOAD = 64
# Issue kinds that describe the log rather than damage to it: never raised in strict mode and
# never make a log "unreadable".
INFO_KINDS = frozenset({"unknown_object", "time_backwards", "dlc_mismatch", "data_lost", "mf4_fallback"})

_FD = int(FrameFlag.FD)


class ChunkBuilder:
    """Preallocated columns that fill up to ``cap`` frames, then hand over as one :class:`FrameChunk`.

    The arrays are public so compiled kernels can write rows ``n..cap-1`` directly. The
    payload buffer is zero-filled and 8 bytes wide until a longer payload arrives (or a
    kernel that may write one calls :meth:`widen`); chunks without CAN FD payloads come out
    8 wide.
    """

    def __init__(self, cap: int) -> None:
        self.cap = cap
        self.n = 0
        self._alloc()

    def _alloc(self) -> None:
        cap = self.cap
        self.t_ns: npt.NDArray[np.int64] = np.empty(cap, np.int64)
        self.channel: npt.NDArray[np.int16] = np.empty(cap, np.int16)
        self.arb_id: npt.NDArray[np.uint32] = np.empty(cap, np.uint32)
        self.flags: npt.NDArray[np.uint8] = np.empty(cap, np.uint8)
        self.dlc: npt.NDArray[np.uint8] = np.empty(cap, np.uint8)
        self.data: npt.NDArray[np.uint8] = np.zeros((cap, 8), np.uint8)

    def widen(self) -> None:
        """Make the payload buffer 64 bytes wide (keeps the rows written so far)."""
        if self.data.shape[1] < MAX_PAYLOAD:
            wide = np.zeros((self.cap, MAX_PAYLOAD), np.uint8)
            wide[: self.n, :8] = self.data[: self.n]
            self.data = wide

    @property
    def full(self) -> bool:
        return self.n >= self.cap

    def add(self, t_ns: int, channel: int, arb_id: int, flags: int, dlc: int, payload: bytes) -> None:
        """Append one frame (``payload`` at most 64 bytes, already validated by the reader)."""
        i = self.n
        self.t_ns[i] = t_ns
        self.channel[i] = channel
        self.arb_id[i] = arb_id
        self.flags[i] = flags
        self.dlc[i] = dlc
        if payload:
            if len(payload) > self.data.shape[1]:
                self.widen()
            self.data[i, : len(payload)] = np.frombuffer(payload, np.uint8)
        self.n = i + 1

    def extend(self, t_ns: npt.NDArray[np.int64], channel: npt.NDArray[np.int64], arb_id: npt.NDArray[np.int64],
               flags: npt.NDArray[np.int64], dlc: npt.NDArray[np.int64],
               data: npt.NDArray[np.uint8]) -> Iterator[FrameChunk]:
        """Append rows in bulk, yielding every chunk that fills up on the way."""
        i, total = 0, len(t_ns)
        width = data.shape[1]
        while i < total:
            if width > self.data.shape[1]:  # again after every hand-over: a fresh builder is 8 wide
                self.widen()
            k = min(self.cap - self.n, total - i)
            rows = slice(self.n, self.n + k)
            self.t_ns[rows] = t_ns[i:i + k]
            self.channel[rows] = channel[i:i + k]
            self.arb_id[rows] = arb_id[i:i + k]
            self.flags[rows] = flags[i:i + k]
            self.dlc[rows] = dlc[i:i + k]
            self.data[rows, :width] = data[i:i + k]
            self.n += k
            i += k
            if self.full:
                yield self.take()

    def take(self) -> FrameChunk:
        """The filled rows as a chunk; the builder starts over with fresh arrays."""
        n = self.n
        wide = bool(np.any((self.dlc[:n] > 8) & ((self.flags[:n] & _FD) != 0)))
        if n == self.cap:  # hand the arrays over; fresh ones are allocated below
            cols = (self.t_ns, self.channel, self.arb_id, self.flags, self.dlc)
        else:  # copies, so the oversized buffers are freed
            cols = (self.t_ns[:n].copy(), self.channel[:n].copy(), self.arb_id[:n].copy(),
                    self.flags[:n].copy(), self.dlc[:n].copy())
        if self.data.shape[1] == 8 or wide:
            data = self.data if n == self.cap else self.data[:n].copy()
        else:
            data = np.ascontiguousarray(self.data[:n, :8])
        chunk = FrameChunk(*cols, data)
        self.n = 0
        self._alloc()
        return chunk


class BaseReader:
    """Common machinery of all readers; see :class:`app.ingest.readers.LogReader` for the contract."""

    fmt: ClassVar[str] = ""

    def __init__(self, stream: ByteStream, head: bytes, *, strict: bool = False, chunk_frames: int = 65536,
                 path: Path | None = None) -> None:
        if chunk_frames < 1:
            raise InputError(f"chunk_frames must be >= 1, got {chunk_frames}")
        self._stream = stream
        self._head = head
        self.path = path
        self.name = stream.name
        self.strict = strict
        self.chunk_frames = chunk_frames
        self.meta = LogMeta(format=self.fmt)
        self.report = IngestReport()
        self._consumed = False
        self._backwards: ReadIssue | None = None
        self._last_t: int | None = None
        self._frame_index = 0
        try:
            self._open()
        except BaseException:
            stream.close()
            raise

    # -- subclass hooks -------------------------------------------------------------------------
    def _open(self) -> None:
        """Parse the header from ``self._head`` (the first bytes) and fill ``self.meta``."""

    def _iter_chunks(self) -> Iterator[FrameChunk]:  # pragma: no cover - abstract
        raise NotImplementedError
        yield

    def limit_work(self, check: Callable[[], None]) -> None:
        """Call ``check`` after every block read from the source; what it raises ends the reading.

        A limit checked only between chunks never fires on a log whose lines are all damaged:
        no chunk is ever complete (``app.ingest.inspect.inspect_log``).
        """
        self._stream.on_read = check

    # -- reporting ------------------------------------------------------------------------------
    @staticmethod
    def where(offset: int | None = None, line: int | None = None) -> str:
        if line is not None:
            return f"line {line}"
        if offset is not None:
            return f"byte offset {offset}"
        return "position unknown"

    def problem(self, kind: str, message: str, *, offset: int | None = None, line: int | None = None,
                count: int = 1, frames_lost: int | None = None, bytes_lost: int | None = None,
                truncated: bool = False) -> ReadIssue:
        """Record a problem (salvage mode) or raise it (strict mode).

        Returns the recorded issue so callers can extend a running entry (e.g. a count).
        """
        if self.strict and kind not in INFO_KINDS:
            exc = TruncatedLogError if truncated else LogFormatError
            raise exc(f"{self.name}: {message} ({self.where(offset, line)})")
        issue = ReadIssue(kind=kind, message=message, offset=offset, line=line, count=count,
                          frames_lost=frames_lost, bytes_lost=bytes_lost)
        self.report.add(issue)
        return issue

    def damage(self, exc: StreamDamage) -> None:
        """Report damage to the compressed stream; reading then ends (the rest is unreachable)."""
        self.problem("truncated" if exc.truncated else "corrupt_gzip", f"gzip stream: {exc}",
                     offset=self._stream.offset, truncated=exc.truncated)

    # -- iteration ------------------------------------------------------------------------------
    def chunks(self) -> Iterator[FrameChunk]:
        """Stream the frames as chunks of at most ``chunk_frames`` rows (single pass)."""
        if self._consumed:
            raise InputError(f"{self.name}: frames were already read; open the log again to re-read it")
        self._consumed = True
        return self._guarded()

    def _guarded(self) -> Iterator[FrameChunk]:
        try:
            for chunk in self._iter_chunks():
                if len(chunk):
                    self._check_order(chunk)
                    self.report.frames += len(chunk)
                    yield chunk
        except AppError:
            raise
        except StreamDamage as exc:  # a reader that did not handle damage itself
            self.damage(exc)
        except (MemoryError, RecursionError):
            raise
        except Exception as exc:  # the boundary: no foreign traceback reaches a user
            raise LogFormatError(f"{self.name}: cannot read this {self.fmt} log: "
                                 f"{type(exc).__name__}: {exc}") from exc
        finally:
            self.close()
        damaged = [i for i in self.report.issues if i.kind not in INFO_KINDS]
        if self.report.frames == 0 and damaged:
            first = damaged[0]
            raise LogFormatError(f"{self.name}: no frames could be read from this {self.fmt} log; first problem: "
                                 f"{first.message} ({self.where(first.offset, first.line)})")

    def _check_order(self, chunk: FrameChunk) -> None:
        """Record backwards time steps (frames stay in logged order) as one merged issue."""
        t = chunk.t_ns
        steps = np.flatnonzero(np.diff(t) < 0) + 1
        first_step = self._last_t is not None and int(t[0]) < self._last_t
        n = len(steps) + int(first_step)
        if n:
            if self._backwards is None:
                idx = self._frame_index if first_step else self._frame_index + int(steps[0])
                self._backwards = self.problem(
                    "time_backwards", f"timestamps step backwards (first before frame index {idx}); "
                    "frames are kept in logged order", count=0)
            self._backwards.count += n
        self._last_t = int(t[-1])
        self._frame_index += len(t)

    # -- progress -------------------------------------------------------------------------------
    @property
    def size(self) -> int | None:
        """Bytes of the log source as stored (compressed for gzip), None when unknown (e.g. a pipe)."""
        return self._stream.size

    def position(self) -> int | None:
        """Bytes of the source consumed so far (0..``size``), None when unknown."""
        return self._stream.position()

    def close(self) -> None:
        self._stream.close()

    def __enter__(self) -> BaseReader:
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self.close()
