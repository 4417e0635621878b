"""candump's screen output with time stamps (``candump -t a|z|A``, no ``-L``): frames, clocks, sniffing,
damage. The samples are written here in the layout the can-utils candump prints."""

from __future__ import annotations

import gzip
from datetime import UTC, datetime
from pathlib import Path

import pytest

from app.errors import LogFormatError, UnsupportedFormatError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import open_log, sniff_format
from app.log_formats import BY_NAME, LOG_FORMATS

EXT, FD, ERR, RTR, BRS, ESI, TX = (int(f) for f in (FrameFlag.EXTENDED, FrameFlag.FD, FrameFlag.ERROR,
                                                    FrameFlag.REMOTE, FrameFlag.BRS, FrameFlag.ESI, FrameFlag.TX))

ABSOLUTE = """\
 (1436509052.249713)  can0  123   [3]  11 22 33
 (1436509052.250001)  can1  1F334455   [2]  AA BB
 (1436509052.251000)  can0  7FF   [0]
 (1436509052.252500)  can0  456   [2]  remote request
 (1436509052.253000)  can0  20000080   [8]  00 00 08 00 00 00 00 00   ERRORFRAME
\tcontroller-problem{rx-error-warning}
 (1436509052.254000)  can1  RX B -  7E8  [12]  00 11 22 33 44 55 66 77 88 99 AA BB
 (1436509052.255000)  can1  TX - E  0CF00400  [08]  01 02 03 04 05 06 07 08
 (1436509052.256000)  can0  TX - -  123   [3]  41 42 43   'ABC'
"""


def _read(path: Path, **kw: object) -> tuple[FrameChunk, object]:
    with open_log(path, **kw) as log:  # type: ignore[arg-type]
        chunk = FrameChunk.concat(list(log.chunks()))
    return chunk, log


def test_absolute_stamps_ids_bytes_and_flags(tmp_path: Path) -> None:
    path = tmp_path / "drive.txt"
    path.write_text(ABSOLUTE)
    assert sniff_format(path.read_bytes(), path.name) == "candump_screen"
    chunk, log = _read(path)
    meta = log.meta  # type: ignore[attr-defined]
    assert meta.format == "candump_screen" and meta.start_clock == "epoch_utc"
    assert meta.start_time == datetime(2015, 7, 10, 6, 17, 32, 249713, tzinfo=UTC)
    assert meta.channels == {0: "can0", 1: "can1"}
    assert log.report.issues == []  # type: ignore[attr-defined]  # the -e explanation line is not a frame
    assert chunk.t_ns.tolist() == [0, 288_000, 1_287_000, 2_787_000, 3_287_000, 4_287_000, 5_287_000, 6_287_000]
    assert chunk.arb_id.tolist() == [0x123, 0x1F334455, 0x7FF, 0x456, 0x80, 0x7E8, 0x0CF00400, 0x123]
    assert chunk.channel.tolist() == [0, 1, 0, 0, 0, 1, 1, 0]
    assert chunk.flags.tolist() == [0, EXT, 0, RTR, ERR, FD | BRS, FD | ESI | EXT | TX, TX]
    assert chunk.dlc.tolist() == [3, 2, 0, 2, 8, 12, 8, 3]
    payloads = [bytes(row[:n]) for row, n in zip(chunk.data, chunk.dlc, strict=True)]
    assert payloads == [b"\x11\x22\x33", b"\xaa\xbb", b"", bytes(2), bytes.fromhex("0000080000000000"),
                        bytes.fromhex("00112233445566778899AABB"), bytes(range(1, 9)), b"ABC"]


def test_zero_based_stamps_keep_no_start(tmp_path: Path) -> None:
    path = tmp_path / "bench.log"
    path.write_text(" (000.000000)  vcan0  100   [1]  01\n (000.010250)  vcan0  100   [1]  02\n"
                    " (001.500000)  vcan0  200   [2]  03 04\n")
    assert sniff_format(path.read_bytes(), path.name) == "candump_screen"  # not candump -L, whatever the suffix
    chunk, log = _read(path)
    assert log.meta.start_time is None and log.meta.start_clock == "unknown"  # type: ignore[attr-defined]
    assert log.meta.extra["clock_at_start_s"] == "0"  # type: ignore[attr-defined]
    assert chunk.t_ns.tolist() == [0, 10_250_000, 1_500_000_000]
    assert chunk.data[:, 0].tolist() == [1, 2, 3]


def test_dated_stamps_are_local_wall_time(tmp_path: Path) -> None:
    path = tmp_path / "dated.txt.gz"
    path.write_bytes(gzip.compress(b" (2015-07-09 19:57:32.249713)  can0  123   [1]  AA\n"
                                   b" (2015-07-09 19:57:33.000000)  can0  123   [1]  BB\n"))
    chunk, log = _read(path)
    assert log.meta.format == "candump_screen"  # type: ignore[attr-defined]
    assert log.meta.start_time == datetime(2015, 7, 9, 19, 57, 32, 249713)  # type: ignore[attr-defined]  # naive
    assert log.meta.start_clock == "candump_date_local"  # type: ignore[attr-defined]
    assert chunk.t_ns.tolist() == [0, 750_287_000]


BROKEN = """\
 (1436509052.000000)  can0  123   [3]  11 22 33
  can0  123   [3]  11 22 33
 (1436509052.001000)  can0  123   [3]  11 22
 (1436509052.002000)  can0  12345   [1]  11
 (1436509052.003000)  can0  123   [9]  11 22 33 44 55 66 77 88 99
 (1436509052.004000)  can0  123   [2]  11 22 33
 (1436509052.005000)  can0  123   [2]  11 G2
 (1436509052.006000)  can0  321   [1]  44
"""


def test_damaged_lines_are_reported_or_raised(tmp_path: Path) -> None:
    path = tmp_path / "cut.txt"
    path.write_text(BROKEN)
    chunk, log = _read(path)
    assert chunk.arb_id.tolist() == [0x123, 0x321]
    issues = log.report.issues  # type: ignore[attr-defined]
    assert [i.line for i in issues] == [2, 3, 4, 5, 6, 7]
    assert [i.kind for i in issues] == ["bad_line", "short_data", "non_hex", "bad_line", "bad_line", "non_hex"]
    assert "no time stamp" in issues[0].message
    with pytest.raises(LogFormatError, match=r"cut\.txt: line skipped: no time stamp .* \(line 2\)"):
        _read(path, strict=True)


def test_the_other_text_formats_keep_their_lines() -> None:
    assert sniff_format(b"(1436509052.249713) can0 123#112233\n" * 3, "x.txt") == "candump"
    assert sniff_format(b"(566.87) RX0 3BE [8] FD 0B 97 00 00 00 00 80\n" * 3, "x.txt") == "serial_dump"
    with pytest.raises(UnsupportedFormatError):  # without -t there is no time: not a log lashscope can read
        sniff_format(b"  can0  123   [3]  11 22 33\n" * 3, "x.txt")


def test_declared_after_the_formats_before_it() -> None:
    names = [f.name for f in LOG_FORMATS]
    assert names.index("candump_screen") == names.index("serial_dump") + 1 and names[-1] == "described"
    assert BY_NAME["candump_screen"].reader_path == "candump_screen:CandumpScreenReader"
