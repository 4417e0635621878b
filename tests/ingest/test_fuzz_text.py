"""Damaged text logs: every bad line is reported with its number and skipped; strict mode stops there.

Covers binary garbage inside an ASC, non-hex bytes, lines shorter than their DLC, negative
timestamps, over-long lines, and the same kinds of damage in candump, TRC and GVRET CSV.
Every case runs with a deadline (see ``run_bounded``) so a hang fails instead of stalling.
"""

from __future__ import annotations

import functools
import gzip
import tempfile
from pathlib import Path

import can
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.errors import LogFormatError, TruncatedLogError
from app.ingest.readers import asc as asc_module
from tests.ingest.test_fuzz_blf import run_bounded
from tests.ingest.test_readers_roundtrip import make_messages


@functools.cache
def _asc_text() -> bytes:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "base.asc"
        with can.ASCWriter(path) as w:
            for m in make_messages(200, fd=True, remote=True, errors=True, seed=3):
                w.on_message_received(m)
        return path.read_bytes()


def _asc_lines() -> list[bytes]:
    """python-can's ASCWriter output for 200 mixed frames, as lines (generated once)."""
    return _asc_text().splitlines(keepends=True)


ASC_DAMAGE = [  # (line, expected issue kind)
    (b"\x00\xff\xfe\x01garbage\x02\x03\n", "bad_line"),
    (b"   1.000000 1  123             Rx   d 8 00 11 22 ZZ 44 55 66 77\n", "non_hex"),
    (b"   1.000000 1  123             Rx   d 8 00 11 22\n", "short_data"),
    (b"  -1.000000 1  123             Rx   d 1 00\n", "bad_timestamp"),
    (b"   1.000000 1  12G             Rx   d 1 00\n", "non_hex"),
    (b"   1.000000 1  123             Rx   d Q 00\n", "non_hex"),
    (b"   1.000000 CANFD   1 Rx 123 1 0 f 64 00 11\n", "short_data"),
    (b"   1.000000 1  123             Rx   d 2 100 11\n", "non_hex"),
    (b"%" * 200_000 + b"\n", "bad_line"),
    (b"this is not an asc line\n", "bad_line"),
]


@pytest.mark.parametrize("fast_path", [True, False], ids=["scanner", "line-parser"])
def test_asc_damage_reported_with_line_numbers(fast_path: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(asc_module, "FAST_PATH_MIN_BYTES", 0 if fast_path else 10**12)
    lines = _asc_lines()
    good = run_bounded(b"".join(lines))
    assert good.chunk is not None and good.report is not None and good.report.ok
    damaged = list(lines)
    where = {}
    for k, (bad, kind) in enumerate(ASC_DAMAGE):
        at = 20 + 15 * k  # 0-based insertion index; with earlier insertions accounted for below
        damaged.insert(at, bad)
        where[at + 1] = kind
    out = run_bounded(b"".join(damaged))
    assert out.chunk is not None and out.report is not None
    assert len(out.chunk) == len(good.chunk)
    got = {i.line: i.kind for i in out.report.issues}
    assert got == where
    assert all(i.line is not None and i.offset is None for i in out.report.issues)
    # strict: the first damaged line stops the read and is named
    strict = run_bounded(b"".join(damaged), strict=True)
    assert isinstance(strict.error, LogFormatError) and f"line {min(where)}" in str(strict.error)


@pytest.mark.parametrize("fast_path", [True, False], ids=["scanner", "line-parser"])
@pytest.mark.parametrize(("line", "kind", "message"), [
    # a garbled byte on a short line names the byte, not the count
    (b"0.001 1 123 Rx d 8 01 02 ZZ\n", "non_hex", "data byte 3 'ZZ' is not a hex number"),
    (b"0.001 1 123 Rx d 8 01 02 03\n", "short_data", "3 data bytes present, 8 expected from the DLC"),
])
def test_asc_bad_byte_is_named_before_the_count(fast_path: bool, monkeypatch: pytest.MonkeyPatch, line: bytes,
                                                kind: str, message: str) -> None:
    monkeypatch.setattr(asc_module, "FAST_PATH_MIN_BYTES", 0 if fast_path else 10**12)
    lines = _asc_lines()
    out = run_bounded(b"".join([*lines[:20], line, *lines[20:]]))
    assert out.report is not None
    assert [(i.line, i.kind, i.message) for i in out.report.issues] == [(21, kind, f"line skipped: {message}")]


def test_asc_gzip_truncated_salvages_and_reports() -> None:
    packed = gzip.compress(_asc_text())
    out = run_bounded(packed[: len(packed) * 2 // 3])
    assert out.chunk is not None and out.report is not None and 0 < len(out.chunk) < 200
    assert [i.kind for i in out.report.issues] == ["truncated"]
    assert isinstance(run_bounded(packed[: len(packed) * 2 // 3], strict=True).error, TruncatedLogError)


SCREEN = " (1436509052.249713)  can0  123   [3]  11 22 33\n"  # candump -t a screen output (candump_screen)
TSV_HEAD = "ParserFlags\tCh\tCounter\tT/R\tTime\tFlags\tCAN ID\tLen\tData\tParser Name\tdefault\n"


@pytest.mark.parametrize(("fmt_text", "bad", "kind"), [
    ("(1.000001) can0 123#00\n", "(abc) can0 123#00\n", "bad_timestamp"),
    ("(1.000001) can0 123#00\n", "(1.000002) can0 12G#00\n", "non_hex"),
    ("(1.000001) can0 123#00\n", "(1.000002) can0 123#0\n", "non_hex"),
    ("(1.000001) can0 123#00\n", "(1.000002) can0 123#112233445566778899\n", "bad_line"),
    ("(1.000001) can0 123#00\n", "(-1.000002) can0 123#00\n", "bad_timestamp"),
    ("Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n1,00000100,false,0,1,AA\n",
     "2,00000100,false,0,8,AA,BB\n", "short_data"),
    ("Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n1,00000100,false,0,1,AA\n",
     "2,00000100,false,0,2,AA,XY\n", "non_hex"),
    ("Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8\n1,00000100,false,0,1,AA\n",
     "2,00000100,maybe,0,1,AA\n", "bad_line"),
    (";$FILEVERSION=2.1\n;$STARTTIME=44548.5\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n      1 1.000 DT 1 0100 Rx -  1 AA\n",
     "      2 2.000 DT 1 0100 Rx -  4 AA BB\n", "short_data"),
    (";$FILEVERSION=1.1\n;$STARTTIME=44548.5\n     1)  1.0  Rx  0100  1  AA\n",
     "     2)  2.0  Rx  0100  2  AA QQ\n", "non_hex"),
    ("000000EAx0CFFAC0100007B0000000000\n", "000000EBx0CFFAC0100007B000000000\n", "short_data"),
    ("000000EAx0CFFAC0100007B0000000000\n", "000000EBx0CFFAC0100007B00000000000000\n", "bad_line"),
    ("000000EAx0CFFAC0100007B0000000000\n", "0000G0EBx0CFFAC0100007B0000000000\n", "bad_timestamp"),
    ("000000EAx0CFFAC0100007B0000000000\n", "000000EBx0CFFAC\n", "bad_line"),
    (TSV_HEAD + "1\t0\t1\tRX\t100\t\t0x00000100\t1\t0xaa \tDefault Parser\t\n",
     "1\t0\t2\tRX\t101\t\t0x00000100\t3\t0xaa bb \tDefault Parser\t\n", "short_data"),
    (TSV_HEAD + "1\t0\t1\tRX\t100\t\t0x00000100\t1\t0xaa \tDefault Parser\t\n",
     "1\t0\t2\tRX\t10x1\t\t0x00000100\t1\t0xaa \tDefault Parser\t\n", "bad_timestamp"),
    (TSV_HEAD + "1\t0\t1\tRX\t100\t\t0x00000100\t1\t0xaa \tDefault Parser\t\n",
     "1\t0\t2\tRX\t101\t\t0x00000100\t1\t0xag \tDefault Parser\t\n", "non_hex"),
    ("(566.87) RX0 3BE [2] FD 0B\n", "(566.88) RX0 3BE [2] FD\n", "short_data"),
    ("(566.87) RX0 3BE [2] FD 0B\n", "(566.88) RX0 3XE [2] FD 0B\n", "non_hex"),
    ("(566.87) RX0 3BE [2] FD 0B\n", "(566.88) RX0 3BE [9] FD 0B\n", "bad_line"),
    ("(566.87) RX0 3BE [2] FD 0B\n", "(56x.88) RX0 3BE [2] FD 0B\n", "bad_timestamp"),
    ("(566.87) RX0 3BE [2] FD 0B\n", " 00 10 00 00\n", "bad_line"),
    (SCREEN, " (1436509052.25x713)  can0  123   [3]  11 22 33\n", "bad_timestamp"),
    (SCREEN, " (-1436509052.259713)  can0  123   [3]  11 22 33\n", "bad_timestamp"),
    (SCREEN, " (1436509052.259713)  can0  1G3   [3]  11 22 33\n", "non_hex"),
    (SCREEN, " (1436509052.259713)  can0  123   [3]  11 2Z 33\n", "non_hex"),
    (SCREEN, " (1436509052.259713)  can0  123   [3]  11 22\n", "short_data"),
    (SCREEN, " (1436509052.259713)  can0  123   [9]  11 22 33 44 55 66 77 88 99\n", "bad_line"),
    (SCREEN, "garbage line here\n", "bad_line"),
])
def test_other_text_formats_damage(fmt_text: str, bad: str, kind: str) -> None:
    good_line = fmt_text.splitlines()[-1] + "\n"
    text = fmt_text + bad + good_line
    out = run_bounded(text.encode())
    assert out.chunk is not None and out.report is not None, out.error
    assert len(out.chunk) == 2
    bad_line_no = fmt_text.count("\n") + 1
    assert [(i.kind, i.line) for i in out.report.issues] == [(kind, bad_line_no)]
    strict = run_bounded(text.encode(), strict=True)
    assert isinstance(strict.error, LogFormatError) and f"line {bad_line_no}" in str(strict.error)


def test_only_garbage_lines_is_an_error() -> None:
    text = b"(1.0) can0 123#00\n" + b"(x) y z\n" * 50
    out = run_bounded(text[18:], fmt="candump")
    assert isinstance(out.error, LogFormatError) and "no frames could be read" in str(out.error)


LINE = st.text(alphabet=st.characters(codec="latin-1", exclude_characters="\r\n"), max_size=120).filter(
    lambda s: not s.strip().lower().startswith(("base", "date")))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, 260), LINE), max_size=8))
def test_random_lines_inside_an_asc_never_cost_valid_frames(inserts: list[tuple[int, str]]) -> None:
    lines = _asc_lines()
    for at, text in sorted(inserts, reverse=True):
        lines.insert(min(at, len(lines)), text.encode("latin-1") + b"\n")
    out = run_bounded(b"".join(lines), fmt="asc")
    assert out.chunk is not None and out.report is not None
    assert len(out.chunk) >= 200


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, 200), LINE), max_size=8))
def test_random_lines_inside_candump_screen_output_never_cost_valid_frames(inserts: list[tuple[int, str]]) -> None:
    """The newest reader under the same abuse as the ASC one: any inserted line is reported or read, never a crash,
    a hang or a lost frame (the format is named: a few garbage lines must not change what the log is)."""
    lines = [f" ({1436509052.0 + 0.01 * i:.6f})  can0  {0x100 + i % 7:03X}   [2]  {i % 256:02X} 7F\n".encode()
             for i in range(200)]
    for at, text in sorted(inserts, reverse=True):
        lines.insert(min(at, len(lines)), text.encode("latin-1") + b"\n")
    out = run_bounded(b"".join(lines), fmt="candump_screen")
    assert out.chunk is not None and out.report is not None, out.error
    assert len(out.chunk) >= 200
