"""ASAM MDF 4 bus logging (as CANedge and asammdf write it): our numpy reader, asammdf for other layouts.

Frames live in channel groups named by their event type, each a structured channel::

    CAN_DataFrame    .BusChannel (1-based) .ID .IDE .DLC .DataLength .DataBytes .Dir .EDL .BRS .ESI
    CAN_RemoteFrame  .BusChannel .ID .IDE .DLC .Dir
    CAN_ErrorFrame   .BusChannel [.ID .IDE ...] .ErrorType

The file is memory-mapped and read by :mod:`mf4_blocks` / :mod:`mf4_native` (no asammdf
import, block-by-block for sorted groups); a layout they do not read goes through asammdf,
recorded as an ``mf4_fallback`` issue with the reason. Both give their columns to
:func:`frames_from_samples`, so the frame rules are one. Groups are read in record blocks of
``chunk_frames`` and merged by time, so memory stays bounded by the chunk size (per group).
``start_time`` is the MDF header's absolute time (stored as UTC ns in the file):
``start_clock = "mf4_header_utc"``. CANedge's compressed or encrypted ``.MFC``/``.MFE`` files
are refused by the sniffer with a clear message.

MDF is read by random access, so a gzip-compressed MF4 (or one handed over as a stream) is
first inflated to a temporary file in 1 MiB blocks -- never into memory -- up to the cap of
every gzipped log (:func:`~app.ingest.readers._source.inflate_cap`: ``LASHSCOPE_MAX_INFLATED_MB``,
default 4096 MiB, and 32x the compressed size). Past the cap the partial file is removed and
:class:`~app.errors.InflatedTooLargeError` names the cap; the temporary file (under the server:
``<data>/tmp``, :mod:`app.tempfiles`) is removed when the reader closes.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
import warnings
from collections.abc import Iterator
from datetime import UTC, datetime
from typing import Any

import numpy as np
import numpy.typing as npt

from app.errors import LogFormatError, StorageError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import mf4_native as native
from app.ingest.readers._base import BaseReader
from app.ingest.readers._source import StreamDamage, inflate_cap, too_large
from app.ingest.readers.mf4_blocks import Damaged, MdfFile, Unsupported
from app.log_formats import LogFormat
from app.settings import Settings
from app.tempfiles import owner_tag

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))
GROUP_KINDS = ("CAN_DataFrame", "CAN_RemoteFrame", "CAN_ErrorFrame")
_BLOCK = 1 << 20


def _field(samples: Any, name: str, n: int, default: int = 0) -> npt.NDArray[np.int64]:
    if samples.dtype.names and name in samples.dtype.names:
        return np.asarray(samples[name]).astype(np.int64)
    return np.full(n, default, np.int64)


def _set(samples: Any, name: str) -> Any:
    """True where an (optional) flag field of the block is non-zero; False when the field is absent."""
    if samples.dtype.names and name in samples.dtype.names:
        return np.asarray(samples[name]) != 0
    return False


def frames_from_samples(kind: str, samples: Any, timestamps: npt.NDArray[np.float64]) -> FrameChunk:
    """Convert one block of an asammdf structured CAN channel into a :class:`FrameChunk`."""
    n = len(timestamps)
    p = kind + "."
    ident = _field(samples, p + "ID", n)
    fl = np.zeros(n, np.uint8)
    fl[_set(samples, p + "IDE") | (ident & 0x80000000 != 0)] |= EXT
    fl[_set(samples, p + "Dir")] |= TX
    data = np.zeros((n, 8), np.uint8)
    if kind == "CAN_DataFrame":
        length = np.clip(_field(samples, p + "DataLength", n), 0, 64)
        for name, bit in (("EDL", FD), ("BRS", BRS), ("ESI", ESI)):
            fl[_set(samples, p + name)] |= bit
        raw = np.asarray(samples[p + "DataBytes"], np.uint8).reshape(n, -1)
        width = 64 if raw.shape[1] > 8 and np.any(length > 8) else 8
        data = np.zeros((n, width), np.uint8)
        w = min(width, raw.shape[1])
        if n and int(length.min()) >= w:  # every frame fills the columns: nothing to blank
            data[:, :w] = raw[:, :w]
        else:
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
                      fl, dlc.astype(np.uint8), data)


FORMAT = LogFormat(name="mf4", reader="MF4Reader", label="MF4", order=60, suffixes=(".mf4", ".mdf"),
                   magic=(b"MDF     ", b"UnFinMF "))


class MF4Reader(BaseReader):
    """MDF 4 bus-logging reader (see the module docstring)."""

    fmt = FORMAT.name

    def _open(self) -> None:
        self._spool: str | None = None
        self._native: MdfFile | None = None
        self._groups: list[tuple[int, str, int]] = []
        if self.path is not None and not self._stream.compressed:
            source: Any = str(self.path)
        else:  # random access needed: a gzip member or a stream goes to a temporary file first
            source = self._spool = self._inflate(*inflate_cap(self._stream.size))
        try:
            try:
                if Settings().mf4_native:  # LASHSCOPE_MF4_NATIVE=false: always through asammdf
                    self._load_native(source)
                    return
            except Unsupported as why:
                self._native = None
                self.problem("mf4_fallback", f"read through asammdf: {why}")
            try:
                import asammdf  # lazy: the fallback for other MF4 layouts
            except ImportError as exc:
                raise LogFormatError(f"{self.name}: this MF4 layout needs the asammdf package") from exc
            self._load(asammdf, source)
        except BaseException:
            self.close()  # removes the temporary file
            raise

    def _load_native(self, source: str) -> None:
        """Open with the numpy reader (:mod:`mf4_native`); a damaged structure is a typed error."""
        try:
            # a plain ndarray over the map: memmap slicing costs a Python call per slice
            self._native = mdf = MdfFile(np.memmap(source, np.uint8, mode="r").view(np.ndarray))
            self._can = native.can_groups(mdf)
            self._split: dict[int, dict[int, Any]] = {}
            problems: native.Problems = []
            for g in self._can:
                if g.dg.record_id_size and id(g.dg) not in self._split:
                    self._split[id(g.dg)] = native.unsorted_records(mdf, g.dg, problems)
                if g.dg.record_id_size:
                    self._vlsd(g)  # a layout it cannot pair raises Unsupported now, not halfway through
        except Damaged as exc:
            raise LogFormatError(f"{self.name}: MF4 structure damaged: {exc} (byte offset {exc.offset})") from exc
        self._report(problems)
        gi = {id(cg): i for i, cg in enumerate(cg for dg in mdf.data_groups for cg in dg.groups)}
        counted = [(gi[id(g.cg)], g.kind, self._count(g)) for g in self._can]
        self._groups = [g for g in counted if g[2] > 0]
        start = datetime.fromtimestamp(mdf.start_ns / 10**9, UTC)
        self.meta.start_time, self.meta.start_clock = start, "mf4_header_utc"
        self.meta.extra["mdf_version"] = f"{mdf.version // 100}.{mdf.version % 100}"
        self.meta.extra["groups"] = ", ".join(f"{kind}[{i}] x{c}" for i, kind, c in self._groups)
        if not self._groups:
            self.problem("no_can_groups", "the file has no CAN_DataFrame/RemoteFrame/ErrorFrame channel group "
                         "with records (not CAN bus logging?)")

    def _count(self, g: native.CanGroup) -> int:
        if g.dg.record_id_size:
            return len(self._split[id(g.dg)][g.cg.record_id])
        if (self._native is not None and self._native.unfinalised & 1) or not g.cg.record_size:
            data = sum(len(leaf) for leaf in self._native.leaves(g.dg.data_link, [])) if self._native else 0
            return data // max(g.cg.record_size, 1)
        return g.cg.cycles

    def _report(self, problems: native.Problems) -> None:
        for kind, offset, message, lost, *frames in problems:
            self.problem(kind, message, offset=offset, bytes_lost=lost or None,
                         frames_lost=frames[0] if frames else None, truncated=kind == "truncated")
        problems.clear()

    def _vlsd(self, g: native.CanGroup) -> Any:
        """The VLSD payload stream of the group's ``.DataBytes`` (None when fixed-width)."""
        mdf = self._native
        assert mdf is not None
        ch = next((c for n, c in g.members.items() if n.endswith(".DataBytes") and c.cn_type == 1), None)
        if ch is None:
            return None
        if g.dg.record_id_size:
            owner = next((cg for cg in g.dg.groups if cg.offset == ch.data_link), None)
            if owner is None:
                raise Unsupported(f"{ch.name}: VLSD data outside its data group")
            return self._split[id(g.dg)][owner.record_id]
        problems: native.Problems = []
        stream = mdf.data(ch.data_link, problems)
        self._report(problems)
        return stream

    def _native_blocks(self, g: native.CanGroup) -> Iterator[FrameChunk]:
        mdf = self._native
        assert mdf is not None
        vlsd = self._vlsd(g)
        step = self.chunk_frames
        problems: native.Problems = []
        if g.dg.record_id_size:
            rec = self._split[id(g.dg)][g.cg.record_id]
            slices: Iterator[Any] = (rec[i:i + step] for i in range(0, len(rec), step))
        else:
            slices = native.sorted_records(mdf, g, problems, step)
        for part in slices:
            samples, t, found = native.group_columns(g, part, vlsd)
            chunk = frames_from_samples(g.kind, samples, t)
            if found is not None and not found.all():
                lost = int(np.count_nonzero(~found))
                self.problem("bad_record", f"{g.kind}: {lost} record(s) whose variable-length payload is missing; "
                             "left out", frames_lost=lost)
                chunk = chunk.select(found)
            yield chunk
            self._report(problems)
        self._report(problems)

    def _load(self, asammdf: Any, source: Any) -> None:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self._mdf: Any = asammdf.MDF(source)
        except Exception as exc:  # asammdf raises many foreign types on damaged files
            raise LogFormatError(f"{self.name}: not a readable MF4 file: {type(exc).__name__}: {exc}") from exc
        self._groups = []
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

    def _inflate(self, cap: int, why: str) -> str:
        """Copy the (decompressed) stream to a temporary file, block by block, refusing more than ``cap`` bytes
        (``why``: the limit that sets the cap)."""
        fd, name = tempfile.mkstemp(prefix=owner_tag(), suffix=".mf4")  # under the server: <data>/tmp
        written = 0
        try:
            with os.fdopen(fd, "wb") as out:
                while block := self._stream.read(_BLOCK):
                    written += len(block)
                    if written > cap:
                        raise too_large(self.name, cap, why)
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
        if self._native is not None:
            try:
                streams = [self._native_blocks(g) for g in self._can if self._count(g) > 0]
                yield from (streams[0] if len(streams) == 1 else merge_by_time(streams, self.chunk_frames))
            except Damaged as exc:
                raise LogFormatError(f"{self.name}: MF4 data damaged: {exc} (byte offset {exc.offset})") from exc
            return
        streams = [self._blocks(*g) for g in self._groups]
        if len(streams) == 1:
            yield from streams[0]
            return
        yield from merge_by_time(streams, self.chunk_frames)

    def close(self) -> None:
        self._native = None  # drops the memory map
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
