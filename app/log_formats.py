"""The log formats lashscope reads: one table, the source of every list of them.

Each entry names a format (the ``format`` of a stored log and of ``open_log(fmt=...)``), the
reader class that reads it (``"module:Class"`` under :mod:`app.ingest.readers`, imported only
when a log of that format is opened), the words a user knows it by, and the suffixes that break
a tie when the content fits several text formats. Help texts, the REST summary, the dashboard's
upload card and the "supported formats" part of an :class:`~app.errors.UnsupportedFormatError`
are all built from it, so adding a reader here is the one place a format gets listed.

It sits outside ``app.ingest`` and imports nothing: the command line builds its help from it without
loading numpy or cantools (``app.ingest``'s package import prepares cantools).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path


@dataclass(frozen=True)
class LogFormat:
    name: str  # key: LogMeta.format, open_log(fmt=...), the stored log's format
    reader: str  # "module:Class" under app.ingest.readers
    label: str  # what a user calls it, in help texts and error messages
    suffixes: tuple[str, ...] = ()  # break ties between text formats whose lines both fit


LOG_FORMATS: tuple[LogFormat, ...] = (
    LogFormat("blf", "blf:BLFReader", "Vector BLF", (".blf",)),
    LogFormat("asc", "asc:ASCReader", "Vector ASC", (".asc",)),
    LogFormat("candump", "candump:CandumpReader", "candump -L", (".log",)),
    LogFormat("trc", "trc:TRCReader", "PEAK TRC", (".trc",)),
    LogFormat("gvret_csv", "gvret_csv:GvretCsvReader", "SavvyCAN/GVRET CSV", (".csv",)),
    LogFormat("mf4", "mf4:MF4Reader", "MF4", (".mf4", ".mdf")),
    LogFormat("tcu", "tcu:TcuReader", "TCU SD-card text"),
    LogFormat("analyser_tsv", "analyser_tsv:AnalyserTsvReader", "USB-CAN analyser tab export"),
    LogFormat("serial_dump", "serial_dump:SerialDumpReader", "serial RXn/TXn dump"),
    LogFormat("described", "described:DescribedReader", "a text format described in a TOML file"),
)

BY_NAME: dict[str, LogFormat] = {f.name: f for f in LOG_FORMATS}
FORMAT_NAMES: tuple[str, ...] = tuple(f.name for f in LOG_FORMATS)
SNIFFED = tuple(n for n in FORMAT_NAMES if n != "described")  # "described" needs its description


def formats_sentence() -> str:
    """The formats in words, for help texts: ``Vector BLF, Vector ASC, ... or a text format described in
    a TOML file; gzip accepted``."""
    labels = [f.label for f in LOG_FORMATS]
    return f"{', '.join(labels[:-1])} or {labels[-1]}; gzip accepted"


def supported_list() -> str:
    """The format keys with their labels, for an error that says what is supported."""
    return ", ".join(f"{f.name} ({f.label})" for f in LOG_FORMATS)


SIDECAR_SUFFIX = ".format.toml"


def sidecar_of(log: Path) -> Path:
    """Where the format description of a text log lives beside it: ``drive.txt`` -> ``drive.txt.format.toml``
    (read by ``open_log`` when no format is given; the service stores an uploaded description so)."""
    return log.with_name(log.name + SIDECAR_SUFFIX)
