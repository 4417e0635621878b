"""The public surface: READERS, sniff_format (content first), open_log sources, chunks, errors."""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import numpy as np
import pytest

from app.errors import InputError, LogFormatError, LogNotFoundError, StorageError, UnsupportedFormatError
from app.ingest.frames import FrameChunk
from app.ingest.readers import FORMATS, READERS, LogReader, open_log, sniff_format
from app.ingest.readers.mf4 import merge_by_time
from tests.ingest.test_readers_blf import blf_file, can_msg, obj

ASC = b"date Thu Apr 28 10:44:52.480 am 2022\nbase hex  timestamps absolute\n   0.001 1  100  Rx   d 1 AA\n"
CANDUMP = b"(1700000000.000001) can0 123#AA\n"
TRC = b";$FILEVERSION=1.1\n;$STARTTIME=44548.5\n     1)  1.0  Rx  0100  1  AA\n"
CSV = b"Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n100,00000100,false,0,1,AA\n"
BLF = blf_file([obj(1, can_msg(1, 0x100, b"\xaa"), 0)])


def test_every_format_is_documented_and_named_in_the_help() -> None:
    """The one list (app/log_formats.py) reaches the docs, the help text and the unsupported-format error."""
    from app.cli.log_args import log_help
    from app.errors import UnsupportedFormatError
    from app.log_formats import LOG_FORMATS

    doc = (Path(__file__).resolve().parents[2] / "docs" / "ingest-readers.md").read_text()
    with pytest.raises(UnsupportedFormatError) as err:
        sniff_format(b"nothing a reader knows\n", "x.txt")
    for f in LOG_FORMATS:
        assert f'`"{f.name}"`' in doc, f.name
        assert f.label in " ".join(log_help().split()), f.label
        assert f"{f.name} ({f.label})" in str(err.value), f.name


def test_readers_table() -> None:
    assert set(READERS) == set(FORMATS) >= {"blf", "asc", "candump", "trc", "gvret_csv", "mf4", "tcu",
                                            "analyser_tsv", "serial_dump", "described"}


@pytest.mark.parametrize(("head", "fmt"), [(ASC, "asc"), (CANDUMP, "candump"), (TRC, "trc"), (CSV, "gvret_csv"),
                                           (BLF, "blf"), (b"MDF     4.10    ", "mf4"), (b"UnFinMF 4.11    ", "mf4")])
@pytest.mark.parametrize("name", [None, "log.blf", "log.asc", "log.csv", "log.bin"])
def test_sniff_by_content_whatever_the_name(head: bytes, fmt: str, name: str | None) -> None:
    assert sniff_format(head, name) == fmt
    assert sniff_format(gzip.compress(head), name and name + ".gz") == fmt


def test_suffix_breaks_ties_only() -> None:
    both = ASC.splitlines()[2] + b"\n" + CANDUMP  # one ASC frame line, one candump line
    assert sniff_format(both, "x.log") == "candump"
    assert sniff_format(both, "x.asc") == "asc"


@pytest.mark.parametrize("junk", [b"hello world\n", bytes(range(256)) * 4, b"\x00" * 100])
def test_unsupported_lists_the_formats(junk: bytes) -> None:
    with pytest.raises(UnsupportedFormatError) as err:
        sniff_format(junk, "x.asc")
    assert all(f in str(err.value) for f in FORMATS)
    assert err.value.status == 415


def test_empty_log() -> None:
    with pytest.raises(LogFormatError, match="empty log"):
        sniff_format(b"")
    with pytest.raises(LogFormatError, match="empty log"):
        open_log(io.BytesIO(b""))
    with pytest.raises(LogFormatError, match="empty log"):
        open_log(io.BytesIO(gzip.compress(b"")))


def test_missing_path_and_unknown_format(tmp_path: Path) -> None:
    with pytest.raises(LogNotFoundError, match="not found") as missing:
        open_log(tmp_path / "nope.blf")
    assert missing.value.code == "file_not_found" and missing.value.status == 404
    assert isinstance(missing.value, FileNotFoundError)
    with pytest.raises(StorageError, match="directory"):
        open_log(tmp_path)
    with pytest.raises(UnsupportedFormatError, match="unknown format 'pcap'"):
        open_log(io.BytesIO(ASC), fmt="pcap")
    with pytest.raises(InputError, match="binary mode"):
        open_log(io.StringIO("x"))  # type: ignore[arg-type]


def test_reader_protocol_context_and_single_pass(tmp_path: Path) -> None:
    path = tmp_path / "x.blf"
    path.write_bytes(BLF)
    with open_log(path) as log:
        assert isinstance(log, LogReader)
        assert len(FrameChunk.concat(log.chunks())) == 1
        with pytest.raises(InputError, match="already read"):
            log.chunks()
    assert log.report.frames == 1


def test_caller_stream_stays_open_and_is_read_from_its_position() -> None:
    stream = io.BytesIO(b"JUNK" + CANDUMP)
    stream.seek(4)
    with open_log(stream) as log:
        assert len(FrameChunk.concat(log.chunks())) == 1
    assert not stream.closed


def test_chunks_are_bounded() -> None:
    text = b"".join(b"(1700000000.%06d) can0 123#AA\n" % i for i in range(1000))
    with open_log(io.BytesIO(text), chunk_frames=64) as log:
        sizes = [len(c) for c in log.chunks()]
    assert max(sizes) == 64 and sum(sizes) == 1000
    with pytest.raises(InputError):
        open_log(io.BytesIO(text), chunk_frames=0)


def test_strict_vs_salvage_on_the_same_damage() -> None:
    text = ASC + b"   0.002 1  100  Rx   d 4 AA\n" + ASC.splitlines()[2] + b"\n"
    with open_log(io.BytesIO(text)) as log:
        assert len(FrameChunk.concat(log.chunks())) == 2
    assert [(i.kind, i.line, i.count) for i in log.report.issues] == [("short_data", 4, 1)]
    with open_log(io.BytesIO(text), strict=True) as log, pytest.raises(LogFormatError, match="line 4"):
        list(log.chunks())


def _chunk(t: list[int], tag: int) -> FrameChunk:
    n = len(t)
    return FrameChunk(np.array(t, np.int64), np.full(n, tag, np.int16), np.arange(n, dtype=np.uint32),
                      np.zeros(n, np.uint8), np.zeros(n, np.uint8), np.zeros((n, 8), np.uint8))


def test_merge_by_time_is_ordered_stable_and_bounded() -> None:
    a = iter([_chunk([0, 5, 10], 0), _chunk([20, 30], 0)])
    b = iter([_chunk([5, 6], 1), _chunk([7, 8, 40], 1)])
    parts = list(merge_by_time([a, b], cap=2))
    merged = FrameChunk.concat(parts)
    assert all(len(p) <= 2 for p in parts)
    assert list(merged.t_ns) == [0, 5, 5, 6, 7, 8, 10, 20, 30, 40]
    assert list(merged.channel[1:3]) == [0, 1]  # equal times keep stream order


@pytest.mark.parametrize("raw", [BLF, CANDUMP, CSV, TRC], ids=["blf", "candump", "csv", "trc"])
def test_any_format_gzipped(raw: bytes) -> None:
    with open_log(io.BytesIO(gzip.compress(raw))) as log:
        assert len(FrameChunk.concat(log.chunks())) == 1
    assert log.report.ok
