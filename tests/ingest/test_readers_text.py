"""Text formats in detail: ASC modes and dates, candump shapes, TRC versions, GVRET header variants."""

from __future__ import annotations

import io
from datetime import UTC, datetime
from pathlib import Path

import pytest

from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import LogReader, open_log
from app.ingest.readers import asc as asc_module
from app.ingest.readers.asc import parse_asc_date
from tests.conftest import sample_files


def read_text(text: str, **kw: object) -> tuple[FrameChunk, LogReader]:
    with open_log(io.BytesIO(text.encode("latin-1")), **kw) as log:  # type: ignore[arg-type]
        chunk = FrameChunk.concat(log.chunks())
    return chunk, log


@pytest.mark.parametrize(("text", "expected", "clock"), [
    ("Thu Apr 28 10:44:52.480 am 2022", datetime(2022, 4, 28, 10, 44, 52, 480000), "asc_date_header_local"),
    ("Tue May 27 04:09:35.000 pm 2014", datetime(2014, 5, 27, 16, 9, 35), "asc_date_header_local"),
    ("Sat Sep 30 12:06:13.191 am 2017", datetime(2017, 9, 30, 0, 6, 13, 191000), "asc_date_header_local"),
    ("Sam Sep 30 15:06:13.191 2017", datetime(2017, 9, 30, 15, 6, 13, 191000), "asc_date_header_local"),
    ("Mo Okt 02 08:00:01.5 2023", datetime(2023, 10, 2, 8, 0, 1, 500000), "asc_date_header_local"),
    ("Thu, 09 Nov 2023 20:29:27 GMT", datetime(2023, 11, 9, 20, 29, 27, tzinfo=UTC), "asc_date_header_utc"),
])
def test_asc_date_header(text: str, expected: datetime, clock: str) -> None:
    assert parse_asc_date(text) == (expected, clock)


@pytest.mark.parametrize("text", ["", "no date here", "Thu Apr 31 10:44:52 2022", "Thu Apr 28 13:44:52 pm 2022"])
def test_asc_unreadable_date_is_none(text: str) -> None:
    assert parse_asc_date(text) is None


ASC_RELATIVE = """date Thu Apr 28 10:44:52.480 am 2022
base hex  timestamps relative
internal events logged
// a comment
Begin TriggerBlock Thu Apr 28 10:44:52.480 am 2022
   0.000000 Start of measurement
   0.010000 1  100             Rx   d 2 01 02
   0.005000 CAN 1 Status:chip status error active
   0.020000 2  1FFFFFFFx       Tx   d 1 FF
   0.001000 1  ErrorFrame
   0.000500 CANFD   2 Rx        7FF  Name                             1 0 d 32 """ + " ".join(["AB"] * 32) + """ 0 0 0
End TriggerBlock
"""


def test_asc_relative_timestamps_accumulate_over_every_event() -> None:
    chunk, log = read_text(ASC_RELATIVE)
    assert log.report.ok, log.report.issues
    assert list(chunk.t_ns) == [10_000_000, 35_000_000, 36_000_000, 36_500_000]
    assert list(chunk.flags) == [0, FrameFlag.EXTENDED | FrameFlag.TX, FrameFlag.ERROR, FrameFlag.FD | FrameFlag.BRS]
    assert list(chunk.channel) == [0, 1, 0, 1]
    assert list(chunk.dlc) == [2, 1, 0, 32] and bytes(chunk.data[3, :32]) == b"\xab" * 32
    assert log.meta.extra["timestamps"] == "relative"
    assert log.meta.start_time == datetime(2022, 4, 28, 10, 44, 52, 480000)


def test_asc_decimal_base() -> None:
    text = "base dec  timestamps absolute\n 1.5 1 256 Rx d 3 1 2 255\n 2.25 1 4096x Tx r 4\n"
    chunk, log = read_text(text)
    assert log.report.ok and list(chunk.arb_id) == [256, 4096]
    assert bytes(chunk.data[0, :3]) == b"\x01\x02\xff"
    assert chunk.flags[1] == FrameFlag.EXTENDED | FrameFlag.TX | FrameFlag.REMOTE and chunk.dlc[1] == 4
    assert list(chunk.t_ns) == [1_500_000_000, 2_250_000_000]


def test_candump_shapes() -> None:
    text = ("(1436509052.249713) vcan0 123#11223344\n"
            "(1436509052.249714) vcan1 1F334455#1122 T\n"
            "(1436509052.249715) vcan0 321##3" + "AA" * 64 + "\n"
            "(1436509052.249716) vcan0 7FF#R\n")
    chunk, log = read_text(text)
    assert log.meta.format == "candump" and log.report.ok
    assert list(chunk.t_ns) == [0, 1000, 2000, 3000]
    assert log.meta.start_time == datetime(2015, 7, 10, 6, 17, 32, 249713, tzinfo=UTC)
    assert list(chunk.channel) == [0, 1, 0, 0] and log.meta.channels == {0: "vcan0", 1: "vcan1"}
    assert list(chunk.flags) == [0, FrameFlag.EXTENDED | FrameFlag.TX, FrameFlag.FD | FrameFlag.BRS | FrameFlag.ESI,
                                 FrameFlag.REMOTE]
    assert list(chunk.dlc) == [4, 2, 64, 0] and chunk.width == 64


def test_trc_v13_bus_column_and_rtr() -> None:
    text = (";$FILEVERSION=1.3\n;$STARTTIME=44548.5\n"
            "     1)      1000.500 2  Rx    18FF0001 -  3    01 02 03\n"
            "     2)      1001.000 1  Tx        0123 -  2    RTR\n"
            "     3)      1002.000 1  Warng FFFFFFFF -  4    00 00 00 08 BUSHEAVY\n")
    chunk, log = read_text(text)
    assert log.meta.format == "trc" and log.report.ok
    assert log.meta.start_time == datetime(2021, 12, 18, 12, 0) and log.meta.start_clock == "trc_header_local"
    assert list(chunk.t_ns) == [1_000_500_000, 1_001_000_000]
    assert list(chunk.channel) == [2, 1]  # the bus numbers as written (1-based), like python-can
    assert list(chunk.flags) == [FrameFlag.EXTENDED, FrameFlag.TX | FrameFlag.REMOTE]


def test_trc_v2_fd_types() -> None:
    text = (";$FILEVERSION=2.1\n;$STARTTIME=44548.5\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n"
            "      1        10.000 FB 1  00000100 Rx -  9    " + " ".join(["11"] * 12) + "\n"
            "      2        11.000 DT 2      0200 Tx -  2    01 02\n"
            "      3        12.000 ST 1         - Rx -  4    00 00 00 08\n")
    chunk, log = read_text(text)
    assert log.report.ok and list(chunk.dlc) == [12, 2]
    assert list(chunk.flags) == [FrameFlag.FD | FrameFlag.BRS | FrameFlag.EXTENDED, FrameFlag.TX]
    assert list(chunk.channel) == [1, 2]


def test_trc_without_a_bus_column_is_bus_1() -> None:
    text = (";$FILEVERSION=2.0\n;$STARTTIME=44548.5\n;$COLUMNS=N,O,T,I,d,l,D\n"
            "      1        10.000 DT      0100 Rx 2    01 02\n")
    chunk, log = read_text(text)
    assert log.report.ok and list(chunk.channel) == [1] and bytes(chunk.data[0, :2]) == b"\x01\x02"


def test_gvret_header_with_dir_column_and_epoch_clock() -> None:
    text = ("Time Stamp,ID,Extended,Dir,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n"
            "1700000000000000,0x0000018F,false,Tx,1,2,AA,BB,\n"
            "1700000000000250,18FF0001,true,Rx,0,0,\n")
    chunk, log = read_text(text)
    assert log.meta.format == "gvret_csv" and log.report.ok
    assert log.meta.start_clock == "epoch_utc"
    assert log.meta.start_time == datetime(2023, 11, 14, 22, 13, 20, tzinfo=UTC)
    assert list(chunk.t_ns) == [0, 250_000]
    assert list(chunk.flags) == [FrameFlag.TX, FrameFlag.EXTENDED] and list(chunk.channel) == [1, 0]
    assert bytes(chunk.data[0, :2]) == b"\xaa\xbb"


ASC_FILES = [p for p in sample_files("", "**/*.asc") if p.stat().st_size < 400_000]


@pytest.mark.parametrize("path", ASC_FILES, ids=lambda p: p.name[:40])
def test_asc_scanner_equals_line_parser(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def read(min_bytes: int) -> tuple[FrameChunk, list[tuple[str, int | None]]]:
        monkeypatch.setattr(asc_module, "FAST_PATH_MIN_BYTES", min_bytes)
        with open_log(path) as log:
            chunk = FrameChunk.concat(log.chunks())
        return chunk, [(i.kind, i.line) for i in log.report.issues]

    fast, fast_issues = read(0)
    slow, slow_issues = read(10**12)
    assert fast_issues == slow_issues
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc", "data"):
        assert (getattr(fast, col) == getattr(slow, col)).all(), col
