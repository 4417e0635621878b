"""ASAM MDF 4 bus logging (as CANedge and asammdf write it), read through asammdf.

Frames live in channel groups named by their event type, each a structured channel::

    CAN_DataFrame    .BusChannel (1-based) .ID .IDE .DLC .DataLength .DataBytes .Dir .EDL .BRS .ESI
    CAN_RemoteFrame  .BusChannel .ID .IDE .DLC .Dir
    CAN_ErrorFrame   .BusChannel [.ID .IDE ...] .ErrorType

Groups are read in record blocks of ``chunk_frames`` and merged by time, so memory stays
bounded by the chunk size (per group). ``start_time`` is the MDF header's absolute time
(stored as UTC ns in the file): ``start_clock = "mf4_header_utc"``. CANedge's compressed or
encrypted ``.MFC``/``.MFE`` files are refused by the sniffer with a clear message.

asammdf reads by random access, so a gzip-compressed MF4 (or one handed over as a stream) is
first inflated to a temporary file in 1 MiB blocks -- never into memory -- up to a cap
(``LASHSCOPE_MAX_INFLATED_MB``, default 4096 MiB; :data:`MAX_INFLATED_BYTES` overrides it).
Past the cap the partial file is removed and :class:`~app.errors.InflatedTooLargeError` names
the cap; the temporary file is removed when the reader closes.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from collections.abc import Iterator
from datetime import UTC
from typing import Any

import numpy as np
import numpy.typing as npt

from app.errors import InflatedTooLargeError, LogFormatError, StorageError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers._base import BaseReader
from app.ingest.readers._source import StreamDamage

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))
GROUP_KINDS = ("CAN_DataFrame", "CAN_RemoteFrame", "CAN_ErrorFrame")
MAX_INFLATED_BYTES: int | None = None  # None: LASHSCOPE_MAX_INFLATED_MB from the settings
_BLOCK = 1 << 20


def inflate_cap() -> int:
    """Bytes a compressed or streamed MF4 may inflate to on disk."""
    if MAX_INFLATED_BYTES is not None:
        return MAX_INFLATED_BYTES
    from app.settings import get_settings

    return int(get_settings().max_inflated_mb * 2**20)


def _field(samples: Any, name: str, n: int, default: int = 0) -> npt.NDArray[np.int64]:
    if samples.dtype.names and name in samples.dtype.names:
        return np.asarray(samples[name]).astype(np.int64)
    return np.full(n, default, np.int64)


def frames_from_samples(kind: str, samples: Any, timestamps: npt.NDArray[np.float64]) -> FrameChunk:
    """Convert one block of an asammdf structured CAN channel into a :class:`FrameChunk`."""
    n = len(timestamps)
    p = kind + "."
    ident = _field(samples, p + "ID", n)
    ide = _field(samples, p + "IDE", n)
    fl = np.where((ide != 0) | (ident & 0x80000000 != 0), EXT, 0)
    fl |= np.where(_field(samples, p + "Dir", n) != 0, TX, 0)
    data = np.zeros((n, 8), np.uint8)
    if kind == "CAN_DataFrame":
        length = np.clip(_field(samples, p + "DataLength", n), 0, 64)
        fl |= np.where(_field(samples, p + "EDL", n) != 0, FD, 0)
        fl |= np.where(_field(samples, p + "BRS", n) != 0, BRS, 0)
        fl |= np.where(_field(samples, p + "ESI", n) != 0, ESI, 0)
        raw = np.asarray(samples[p + "DataBytes"], np.uint8).reshape(n, -1)
        width = 64 if raw.shape[1] > 8 and np.any(length > 8) else 8
        data = np.zeros((n, width), np.uint8)
        w = min(width, raw.shape[1])
        keep = np.arange(w)[None, :] < length[:, None]  # bytes past DataLength are not data
        data[:, :w] = np.where(keep, raw[:, :w], 0)
        dlc = length
    elif kind == "CAN_RemoteFrame":
        fl |= RTR
        dlc = np.clip(_field(samples, p + "DLC", n), 0, 15)
    else:
        fl |= ERR
        dlc = np.zeros(n, np.int64)
    t_ns = np.rint(np.asarray(timestamps, np.float64) * 1e9).astype(np.int64)
    channel = np.clip(_field(samples, p + "BusChannel", n, default=1) - 1, -1, 32767)
    return FrameChunk(t_ns, channel.astype(np.int16), (ident & 0x1FFFFFFF).astype(np.uint32),
                      fl.astype(np.uint8), dlc.astype(np.uint8), data)


class MF4Reader(BaseReader):
    """MDF 4 bus-logging reader (see the module docstring)."""

    fmt = "mf4"

    def _open(self) -> None:
        try:
            import asammdf
        except ImportError as exc:  # pragma: no cover - a declared dependency
            raise LogFormatError(f"{self.name}: reading MF4 needs the asammdf package") from exc
        self._spool: str | None = None
        if self.path is not None and not self._stream.compressed:
            source: Any = str(self.path)
        else:  # asammdf needs random access: a gzip member or a stream goes to a temporary file first
            source = self._spool = self._inflate(inflate_cap())
        try:
            self._load(asammdf, source)
        except BaseException:
            self.close()  # removes the temporary file
            raise

    def _load(self, asammdf: Any, source: Any) -> None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._mdf: Any = asammdf.MDF(source)
        except Exception as exc:  # asammdf raises many foreign types on damaged files
            raise LogFormatError(f"{self.name}: not a readable MF4 file: {type(exc).__name__}: {exc}") from exc
        self._groups: list[tuple[int, str, int]] = []
        try:
            groups: list[Any] = list(self._mdf.groups)
            for gi, group in enumerate(groups):
                names = {ch.name for ch in group.channels}
                cycles = int(group.channel_group.cycles_nr)
                for kind in GROUP_KINDS:
                    if kind in names and cycles > 0:
                        self._groups.append((gi, kind, cycles))
            start = self._mdf.header.start_time
        except Exception as exc:
            raise LogFormatError(f"{self.name}: MF4 structure unreadable: {type(exc).__name__}: {exc}") from exc
        if start is not None:
            aware = start if start.tzinfo else start.replace(tzinfo=UTC)
            self.meta.start_time = aware.astimezone(UTC)
            self.meta.start_clock = "mf4_header_utc"
        self.meta.extra["mdf_version"] = str(self._mdf.version)
        self.meta.extra["groups"] = ", ".join(f"{kind}[{gi}] x{c}" for gi, kind, c in self._groups)
        if not self._groups:
            self.problem("no_can_groups", "the file has no CAN_DataFrame/RemoteFrame/ErrorFrame channel group "
                         "with records (not CAN bus logging?)")

    def _inflate(self, cap: int) -> str:
        """Copy the (decompressed) stream to a temporary file, block by block, refusing more than ``cap`` bytes."""
        fd, name = tempfile.mkstemp(prefix="lashscope-", suffix=".mf4")
        written = 0
        try:
            with os.fdopen(fd, "wb") as out:
                while block := self._stream.read(_BLOCK):
                    written += len(block)
                    if written > cap:
                        raise InflatedTooLargeError(
                            f"{self.name}: decompresses to more than the {cap / 2**20:g} MiB cap for compressed MF4 "
                            "logs (LASHSCOPE_MAX_INFLATED_MB); decompress it yourself or raise the cap")
                    out.write(block)
        except StreamDamage as exc:
            os.unlink(name)
            raise LogFormatError(f"{self.name}: gzip stream damaged: {exc}") from exc
        except OSError as exc:
            os.unlink(name)
            raise StorageError(f"{self.name}: cannot write the decompressed MF4 to a temporary file: "
                               f"{exc.strerror or exc}") from exc
        except BaseException:
            os.unlink(name)
            raise
        return name

    def _blocks(self, gi: int, kind: str, cycles: int) -> Iterator[FrameChunk]:
        step = self.chunk_frames
        for offset in range(0, cycles, step):
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    sig = self._mdf.get(kind, group=gi, record_offset=offset, record_count=step, raw=True)
                chunk = frames_from_samples(kind, sig.samples, sig.timestamps)
            except Exception as exc:
                self.problem("bad_record", f"{kind} group {gi}: records {offset}..{offset + step - 1} unreadable "
                             f"({type(exc).__name__}: {exc}); skipped", offset=None,
                             frames_lost=min(step, cycles - offset))
                continue
            yield chunk

    def position(self) -> int | None:
        """asammdf reads the file by random access: estimated from the records handed out so far."""
        total = sum(c for _, _, c in self._groups)
        if self.size is None:
            return None
        if not total:
            return self.size if self._consumed else 0
        return min(self.size, self.size * self.report.frames // total)

    def _iter_chunks(self) -> Iterator[FrameChunk]:
        streams = [self._blocks(*g) for g in self._groups]
        if len(streams) == 1:
            yield from streams[0]
            return
        yield from merge_by_time(streams, self.chunk_frames)

    def close(self) -> None:
        mdf = getattr(self, "_mdf", None)
        if mdf is not None:
            self._mdf = None
            with contextlib.suppress(Exception):  # closing a damaged file must not mask the real error
                mdf.close()
        spool = getattr(self, "_spool", None)
        if spool is not None:
            self._spool = None
            with contextlib.suppress(OSError):
                os.unlink(spool)
        super().close()


def merge_by_time(streams: list[Iterator[FrameChunk]], cap: int) -> Iterator[FrameChunk]:
    """Merge time-ordered chunk streams into time-ordered chunks of at most ``cap`` rows (stable)."""
    buffers: list[FrameChunk | None] = [next(s, None) for s in streams]
    while True:
        live = [i for i, b in enumerate(buffers) if b is not None and len(b)]
        if not live:
            return
        # rows up to the smallest "last time" of the open streams cannot be overtaken later
        horizon = min(int(buffers[i].t_ns[-1]) for i in live)  # type: ignore[union-attr]
        parts = []
        for i in live:
            b = buffers[i]
            assert b is not None
            k = int(np.searchsorted(b.t_ns, horizon, side="right"))
            parts.append(b.select(np.arange(len(b)) < k))
            rest = b.select(np.arange(len(b)) >= k)
            buffers[i] = rest if len(rest) else next(streams[i], None)
        merged = FrameChunk.concat(parts)
        order = np.argsort(merged.t_ns, kind="stable")
        merged = FrameChunk(merged.t_ns[order], merged.channel[order], merged.arb_id[order], merged.flags[order],
                            merged.dlc[order], merged.data[order])
        for start in range(0, len(merged), cap):
            piece = merged.select((np.arange(len(merged)) >= start) & (np.arange(len(merged)) < start + cap))
            yield piece
