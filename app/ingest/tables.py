"""Decoded messages streamed to one Parquet/CSV table per message, with bounded memory.

A log is decoded chunk by chunk; every chunk holds a few rows of many messages. Writing each
chunk's rows at once would make tiny Parquet row groups; keeping every message until the end
would hold the whole decoded log in memory. :class:`MessageTables` keeps a buffer per message
and writes a message's rows (one row group, and the same rows to its CSV) when it reaches
``rows_per_group`` rows, and writes the largest buffers whenever all buffers together exceed
``budget_bytes``. Memory is therefore bounded by the budget plus one chunk, whatever the log's
length or the number of messages.

Table layout (as before): ``t_s`` (float64, s since the measurement start), ``bus`` (int16,
0-based log channel), then one float64 column per signal (NaN = absent or not available).
"""

from __future__ import annotations

import re
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from app.errors import StorageError
from app.ingest import arrow
from app.ingest.decode import DecodedMessage

FORMATS = ("parquet", "csv")


def safe_name(name: str) -> str:
    """A file name for a message name (characters outside ``[A-Za-z0-9_.@-]`` become ``_``)."""
    return re.sub(r"[^A-Za-z0-9_.@-]+", "_", name) or "message"


@dataclass
class _Buffer:
    parts: list[DecodedMessage] = field(default_factory=list)
    rows: int = 0
    nbytes: int = 0
    writers: dict[str, Any] = field(default_factory=dict)  # format -> open pyarrow writer
    written: int = 0  # rows written so far


class MessageTables:
    """Write decoded messages to ``folder/<Message>.<fmt>`` as they come (see the module docstring).

    Parameters
    ----------
    folder : Path
        Created when the first table is written.
    formats : iterable of str
        ``"parquet"`` and/or ``"csv"``.
    rows_per_group : int
        Rows of one message written together (a Parquet row group).
    budget_bytes : int
        Decoded rows held in memory across all messages before the largest buffers are written.
    """

    def __init__(self, folder: Path, formats: Iterable[str] = FORMATS, *, rows_per_group: int = 65536,
                 budget_bytes: int = 64 << 20) -> None:
        self.folder = folder
        self.formats = tuple(formats)
        bad = [f for f in self.formats if f not in FORMATS]
        if bad or not self.formats:
            raise ValueError(f"formats must be among {FORMATS}, got {self.formats}")
        self.rows_per_group = rows_per_group
        self.budget_bytes = budget_bytes
        self._buffers: dict[str, _Buffer] = {}
        self._held = 0
        self.peak_bytes = 0  # largest amount of decoded data held at once (for tests and the report)
        self.paths: list[Path] = []

    def add(self, decoded: dict[str, DecodedMessage]) -> None:
        """Buffer one chunk's decoded messages; write what is due."""
        for name, dm in decoded.items():
            if not len(dm):
                continue
            buf = self._buffers.setdefault(name, _Buffer())
            size = dm.t_ns.nbytes + dm.channel.nbytes + sum(v.nbytes for v in dm.signals.values())
            buf.parts.append(dm)
            buf.rows += len(dm)
            buf.nbytes += size
            self._held += size
            self.peak_bytes = max(self.peak_bytes, self._held)
            if buf.rows >= self.rows_per_group:
                self._write(name, buf)
        while self._held > self.budget_bytes:
            name, buf = max(self._buffers.items(), key=lambda kv: kv[1].nbytes)
            self._write(name, buf)

    def close(self) -> list[Path]:
        """Write what is buffered, close every file; the paths written (sorted by message)."""
        try:
            for name, buf in self._buffers.items():
                if buf.rows:
                    self._write(name, buf)
        finally:
            for buf in self._buffers.values():
                for w in buf.writers.values():
                    w.close()
                buf.writers.clear()
        return sorted(self.paths)

    def _write(self, name: str, buf: _Buffer) -> None:

        dm = DecodedMessage.concat(buf.parts)
        cols: dict[str, Any] = {"t_s": dm.t_ns / 1e9, "bus": dm.channel}
        cols.update({s: v for s, v in dm.signals.items() if s not in cols})
        table = arrow.table(cols)
        base = self.folder / safe_name(name)
        try:
            for fmt in self.formats:
                writer = buf.writers.get(fmt)
                if writer is None:
                    self.folder.mkdir(parents=True, exist_ok=True)
                    path = base.with_suffix(f".{fmt}")
                    writer = (pq.ParquetWriter(path, table.schema) if fmt == "parquet"
                              else pacsv.CSVWriter(path, table.schema))
                    buf.writers[fmt] = writer
                    self.paths.append(path)
                if fmt == "parquet":
                    writer.write_table(table, row_group_size=table.num_rows)  # one row group per write
                else:
                    writer.write_table(table)
        except OSError as exc:
            raise StorageError(f"cannot write decoded data to {self.folder}: {exc.strerror or exc}") from exc
        self._held -= buf.nbytes
        buf.written += buf.rows
        buf.parts, buf.rows, buf.nbytes = [], 0, 0

    @property
    def held_bytes(self) -> int:
        """Decoded data buffered right now."""
        return self._held

    def rows_written(self) -> dict[str, int]:
        return {name: buf.written for name, buf in self._buffers.items()}

