"""CAN log readers, chosen by content (each reader module declares its format; :mod:`app.log_formats` collects them).

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
from collections.abc import Callable, Iterator
from types import TracebackType
from typing import BinaryIO, Protocol, runtime_checkable

from app.ingest.frames import FrameChunk, IngestReport, LogMeta
from app.ingest.readers._base import BaseReader
from app.ingest.readers._source import open_source
from app.ingest.readers.described import TextLayout, load_layout
from app.ingest.readers.sniff import FORMATS, sniff_format, sniff_source, unsupported
from app.log_formats import LOG_FORMATS, sidecar_of

__all__ = ["FORMATS", "READERS", "LogReader", "TextLayout", "load_layout", "open_log", "reader_class", "sniff_format"]


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

    def limit_work(self, check: Callable[[], None]) -> None:
        """Call ``check`` after every block read from the source; what it raises ends the reading."""

    def close(self) -> None: ...

    def __enter__(self) -> LogReader: ...

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None,
                 tb: TracebackType | None) -> None: ...


READERS: dict[str, str] = {f.name: f.reader_path for f in LOG_FORMATS}  # format -> "module:Class", imported when needed


def reader_class(fmt: str) -> type[BaseReader]:
    """The reader class of a format (a key of ``READERS``)."""
    module, name = READERS[fmt].split(":")
    cls: type[BaseReader] = getattr(importlib.import_module(f"app.ingest.readers.{module}"), name)
    return cls


def open_log(source: str | os.PathLike[str] | BinaryIO, *, fmt: str | None = None, strict: bool = False,
             chunk_frames: int = 65536, layout: TextLayout | str | os.PathLike[str] | None = None) -> LogReader:
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
    layout : TextLayout or path, optional
        A text format description (:mod:`app.ingest.readers.described`) to read the log with,
        instead of recognising its format. Without one, a description beside a log file
        (``drive.txt.format.toml`` for ``drive.txt``) is used; the service stores an uploaded
        description that way.

    Raises
    ------
    LogFormatError
        Empty file, damaged header, or (strict) any damage found while opening.
    UnsupportedFormatError
        The content matches no supported format, or ``fmt`` is unknown.
    LogNotFoundError
        No file at the path (code ``file_not_found``).
    FormatFileError
        ``layout`` names a description file that is missing or wrong (code ``format_file``).
    StorageError
        The path cannot be opened otherwise.
    """
    if layout is not None and not isinstance(layout, TextLayout):
        layout = load_layout(layout)
    stream, head, path = open_source(source)
    try:
        if layout is None and fmt is None and path is not None and (side := sidecar_of(path)).is_file():
            layout = load_layout(side)
        if layout is not None:
            fmt = "described"
        elif fmt is None:
            fmt, layout = sniff_source(head, stream.name)
        elif fmt not in READERS:
            raise unsupported(stream.name, f"unknown format {fmt!r}")
        elif fmt == "described":
            raise unsupported(stream.name, "format 'described' needs a format description (layout=, --format-file)")
        cls = reader_class(fmt)
        extra = {"layout": layout} if layout is not None else {}
        reader: LogReader = cls(stream, head, strict=strict, chunk_frames=chunk_frames, path=path, **extra)
        return reader
    except BaseException:
        stream.close()
        raise
