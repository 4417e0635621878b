"""Record a live bus to BLF through python-can's writer, losing at most ~a second on a crash.

python-can's :class:`can.BLFWriter` keeps up to 128 KiB of objects in memory before it
compresses them into a container, and writes the file header (start time, object
count) only in ``stop()``. A recording process that is killed therefore loses minutes of
frames at low bus load and leaves a header without a start time. :class:`FlushingBLFWriter`
changes exactly those two things and nothing about the format:

* a container is written whenever ``flush_interval_s`` (default 0.5 s) has passed since the
  last one, even if it is small, and handed to the OS (``flush``); ``os.fsync`` follows at most
  once per ``fsync_interval_s`` so a power cut is covered too;
* the start time is pinned when the file is created and the header is written with it at
  once, so a file cut off by a crash still carries its absolute start time. ``stop()``
  rewrites the header with the final size and object count as usual.

A file cut off mid-container has the containers before it intact; python-can's
``BLFReader`` and lashscope's reader read them back (see ``tests/live/test_recorder.py``).

This leans on two private methods of ``BLFWriter`` (``_flush`` and ``_write_header``),
present since python-can 4.0; the constructor checks for them and fails clearly otherwise.
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import can
from can.io.blf import FILE_HEADER_SIZE

from app.errors import StorageError


class FlushingBLFWriter(can.BLFWriter):
    """``can.BLFWriter`` that flushes a container at least every ``flush_interval_s``.

    Parameters
    ----------
    file : path
        Destination (created or truncated).
    start_time : float
        Absolute time (Unix s, python-can's ``Message.timestamp`` clock) of the
        measurement start; frame times are stored relative to it (ms-truncated, as BLF does).
    flush_interval_s, fsync_interval_s : float
        Upper bounds for data held in memory / not yet on stable storage.
    compression_level : int
        zlib level; 1 keeps the CPU cost low for small frequent containers.
    """

    def __init__(self, file: str | Path, start_time: float, *, flush_interval_s: float = 0.5,
                 fsync_interval_s: float = 1.0, compression_level: int = 1, **kwargs: Any) -> None:
        for name in ("_flush", "_write_header"):
            if not callable(getattr(can.BLFWriter, name, None)):
                raise StorageError(f"python-can {can.__version__} BLFWriter lacks {name}; cannot record BLF safely")
        try:
            super().__init__(str(file), compression_level=compression_level, **kwargs)
        except OSError as exc:
            raise StorageError(f"cannot create recording {file}: {exc}") from exc
        self.flush_interval_s = flush_interval_s
        self.fsync_interval_s = fsync_interval_s
        self.start_timestamp = int(start_time * 1000) / 1000
        self.file.seek(0)
        self._write_header(FILE_HEADER_SIZE)
        self.file.seek(0, os.SEEK_END)
        self.file.flush()
        now = time.monotonic()
        self._last_flush = now
        self._last_fsync = now
        self.frames = 0

    def on_message_received(self, msg: can.Message) -> None:
        super().on_message_received(msg)
        self.frames += 1

    def flush_due(self, now: float | None = None) -> bool:
        now = time.monotonic() if now is None else now
        return bool(self._buffer_size) and now - self._last_flush >= self.flush_interval_s

    def flush(self, *, sync: bool | None = None) -> None:
        """Write buffered objects as a container, hand them to the OS, fsync if due (or if ``sync``)."""
        if self.file.closed:
            return
        now = time.monotonic()
        self._flush()
        self.file.flush()
        self._last_flush = now
        if sync or (sync is None and now - self._last_fsync >= self.fsync_interval_s):
            os.fsync(self.file.fileno())
            self._last_fsync = now

    def tick(self) -> None:
        """Call regularly (also when the bus is silent) to honour the flush interval."""
        if self.flush_due():
            self.flush()

    def stop(self) -> None:
        if not self.file.closed:
            self.file.flush()
        super().stop()
