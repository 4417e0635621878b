"""The log formats lashscope reads: one table, the source of every list of them.

Each entry names a format (the ``format`` of a stored log and of ``open_log(fmt=...)``), the
reader class that reads it (``"module:Class"`` under :mod:`app.ingest.readers`, imported only
when a log of that format is opened), the words a user knows it by, the suffixes that break
a tie when the content fits several text formats, and how the sniffer knows it: the magic bytes of
a binary format, or the shapes of lines only that text format has. Help texts, the REST summary, the dashboard's
upload card and the "supported formats" part of an :class:`~app.errors.UnsupportedFormatError`
are all built from it, and so is the sniffer (:mod:`app.ingest.readers.sniff`): a new reader is its
module plus one entry here.

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
    magic: tuple[bytes, ...] = ()  # the first bytes of every log of a binary format (the sniffer's test)
    lines: tuple[str, ...] = ()  # regular expressions (inline flags) of lines only this text format has: the
    # sniffer scores a text head by how many of its first lines match one of them


ASC_EVENT = r"(?i)^\s*\d+\.\d+\s+(\d+\s+\w+x?\s+(Rx|Tx)\b|\d+\s+ErrorFrame|CANFD\s+\d+)"
GVRET_ROW = r"(?i)^\d+(\.\d+)?,(0x)?[0-9A-Fa-f]{1,8},(true|false),((Rx|Tx),)?\d+,\d+(,[0-9A-Fa-f]{1,2})*,?\s*$"
ANALYSER_HEADER = r"(?i)^\ufeff?ParserFlags\tCh\tCounter\tT/R\tTime\t"
ANALYSER_ROW = r"(?i)^\d+\t\d+\t\d+\t(RX|TX)\t\d+(\.\d+)?\t[^\t]*\t(0x)?[0-9A-Fa-f]{1,8}\t\d+\t"

LOG_FORMATS: tuple[LogFormat, ...] = (
    LogFormat("blf", "blf:BLFReader", "Vector BLF", (".blf",), magic=(b"LOGG",)),
    LogFormat("asc", "asc:ASCReader", "Vector ASC", (".asc",), lines=(
        r"(?i)^\s*date\s+\S+", r"(?i)^\s*base\s+(hex|dec)\b", r"(?i)^\s*(no\s+)?internal\s+events\s+logged",
        r"(?i)^\s*begin\s+triggerblock", ASC_EVENT)),
    LogFormat("candump", "candump:CandumpReader", "candump -L", (".log",),
              lines=(r"^\s*\(\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]{3,8}#",)),
    LogFormat("trc", "trc:TRCReader", "PEAK TRC", (".trc",), lines=(
        r"^;\$(FILEVERSION|STARTTIME|COLUMNS)=", r"^\s*\d+\)\s+\d+(\.\d+)?\s+",
        r"^\s*\d+\s+\d+\.\d+\s+(DT|FD|FB|FE|BI|RR|ST|ER|EC|EV)\s")),
    LogFormat("gvret_csv", "gvret_csv:GvretCsvReader", "SavvyCAN/GVRET CSV", (".csv",),
              lines=(r"(?i)^\s*Time Stamp,ID,Extended,(Dir,)?Bus,LEN", GVRET_ROW)),
    LogFormat("mf4", "mf4:MF4Reader", "MF4", (".mf4", ".mdf"), magic=(b"MDF     ", b"UnFinMF ")),
    LogFormat("tcu", "tcu:TcuReader", "TCU SD-card text",
              lines=(r"^[0-9A-Fa-f]{8}x[0-9A-Fa-f]{8}(?:[0-9A-Fa-f]{2}){0,8}\s*$",)),
    LogFormat("analyser_tsv", "analyser_tsv:AnalyserTsvReader", "USB-CAN analyser tab export",
              lines=(ANALYSER_HEADER, ANALYSER_ROW)),
    LogFormat("serial_dump", "serial_dump:SerialDumpReader", "serial RXn/TXn dump",
              lines=(r"^\(\d+(\.\d+)?\)\s+[RT]X\d+\s+[0-9A-Fa-f]{1,8}\s+\[\d+\]",)),
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
