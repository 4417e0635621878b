"""CAN log readers, chosen by content: BLF, ASC, candump -L, PEAK TRC, SavvyCAN/GVRET CSV, MF4, TCU text.

Usage::

    from app.ingest.readers import open_log

    with open_log("drive.blf") as log:          # format sniffed from the bytes
        print(log.meta.start_time, log.meta.start_clock)
        for chunk in log.chunks():             # FrameChunk, at most chunk_frames rows each
            ...
            print(log.position() / log.size)   # progress (size/position are None when unknown)
        for issue in log.report.issues:        # every skipped/corrupt region, with offset or line
            ...

Salvage mode (``strict=False``, the default) reads what is readable and records every
problem in ``report``; strict mode raises :class:`~app.errors.LogFormatError` (or
:class:`~app.errors.TruncatedLogError`) at the first problem, naming the byte offset or
line. Problems found by ``chunks()`` are raised from the iteration. See
``docs/ingest-readers.md`` for the formats and the report entry kinds.
"""

from __future__ import annotations

import importlib
import os
from collections.abc import Iterator
from types import TracebackType
from typing import BinaryIO, Protocol, runtime_checkable

from app.ingest.frames import FrameChunk, IngestReport, LogMeta
from app.ingest.readers._base import BaseReader
from app.ingest.readers._source import open_source
from app.ingest.readers.sniff import FORMATS, sniff_format, unsupported

__all__ = ["FORMATS", "READERS", "LogReader", "open_log", "reader_class", "sniff_format"]


@runtime_checkable
class LogReader(Protocol):
    """An open log: metadata and report, frames streamed in bounded chunks; a context manager."""

    meta: LogMeta
    report: IngestReport

    def chunks(self) -> Iterator[FrameChunk]: ...

    @property
    def size(self) -> int | None:
        """Bytes of the log as stored (compressed for gzip); None when unknown (a pipe)."""

    def position(self) -> int | None:
        """Bytes of the log consumed so far (``position() / size`` is the progress); None when unknown."""

    def close(self) -> None: ...

    def __enter__(self) -> LogReader: ...

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None: ...


READERS: dict[str, str] = {  # format -> "module:class"; a reader's module is imported when a log needs it
    "blf": "blf:BLFReader",
    "asc": "asc:ASCReader",
    "candump": "candump:CandumpReader",
    "trc": "trc:TRCReader",
    "gvret_csv": "gvret_csv:GvretCsvReader",
    "mf4": "mf4:MF4Reader",
    "tcu": "tcu:TcuReader",
}


def reader_class(fmt: str) -> type[BaseReader]:
    """The reader class of a format (a key of ``READERS``)."""
    module, name = READERS[fmt].split(":")
    cls: type[BaseReader] = getattr(importlib.import_module(f"app.ingest.readers.{module}"), name)
    return cls


def open_log(source: str | os.PathLike[str] | BinaryIO, *, fmt: str | None = None, strict: bool = False,
             chunk_frames: int = 65536) -> LogReader:
    """Open a CAN log for streaming.

    Parameters
    ----------
    source : path or binary file object
        The log; gzip-compressed content (any name) is inflated transparently.
    fmt : str, optional
        Force a format (a key of ``READERS``) instead of sniffing the content.
    strict : bool
        Raise at the first problem instead of salvaging and reporting.
    chunk_frames : int
        Maximum rows per :class:`~app.ingest.frames.FrameChunk` (memory bound).

    Raises
    ------
    LogFormatError
        Empty file, damaged header, or (strict) any damage found while opening.
    UnsupportedFormatError
        The content matches no supported format, or ``fmt`` is unknown.
    LogNotFoundError
        No file at the path (code ``file_not_found``).
    StorageError
        The path cannot be opened otherwise.
    """
    stream, head, path = open_source(source)
    try:
        if fmt is None:
            fmt = sniff_format(head, stream.name)
        elif fmt not in READERS:
            raise unsupported(stream.name, f"unknown format {fmt!r}")
        cls = reader_class(fmt)
        reader: LogReader = cls(stream, head, strict=strict, chunk_frames=chunk_frames, path=path)
        return reader
    except BaseException:
        stream.close()
        raise
