"""The vectorised ASC scanner against the line parser on generated logs that mix every line kind.

The logs (fixed seed) interleave scanner lines (classic frames of every width, extended IDs,
Tx, 1-digit bytes, trailing fields) with lines only the parser reads (CAN FD, error and
remote frames, events, comments, blank lines, damaged lines, control bytes, CRLF, long
timestamps), in both time modes and with a ``base dec`` line in the middle. Each is read
twice, once with the scanner and once line by line, and must give the same frames, issues
and line numbers; spot values are checked against what the lines say.
"""

from __future__ import annotations

import io

import numpy as np
import pytest

from app.ingest.frames import FrameChunk, FrameFlag, group_rows
from app.ingest.readers import asc as asc_module
from app.ingest.readers import open_log
from app.ingest.readers.asc_scan import scan_block


def _line(rng: np.random.Generator, t: float, dec: bool) -> bytes:
    kind = int(rng.integers(0, 22))
    ts = f"{t:.6f}"
    if dec:
        return f"{ts} 1 {rng.integers(0, 2048)} Rx d 2 {rng.integers(0, 256)} {rng.integers(0, 256)}\n".encode()
    if kind < 12:  # the scanner's shape, in its variants
        n = int(rng.integers(0, 9))
        ident = f"{rng.integers(0, 0x1FFFFFFF):X}x" if kind % 3 == 0 else f"{rng.integers(0, 0x800):X}"
        data = " ".join(f"{b:X}" if kind == 5 else f"{b:02X}" for b in rng.integers(0, 256, n))
        tail = "  Length = 228000 BitCount = 118 ID = 100" if kind == 7 else ""
        direction = "Tx" if kind == 4 else "Rx"
        return f"   {ts} {rng.integers(1, 5)}  {ident:<15} {direction}   d {n} {data}{tail}\n".encode()
    other = [
        f"   {ts} CANFD   1 Rx 1C4D80A7x  1 0 9 12 " + " ".join(["AB"] * 12) + "\n",
        f"   {ts} 1  ErrorFrame\n",
        f"   {ts} 2  123             Rx   r 4\n",
        f"   {ts} 1  Statistic: D 0 R 0 XD 0 XR 0 E 0 O 0 B 0.00%\n",
        "// a comment\n",
        "\n",
        f"   {ts} 1  123             Rx   d 8 00 11 22 ZZ 44 55 66 77\n",  # damaged: non_hex
        f"   {ts} 1  123             Rx   d 2 01\x07 02\n",  # control byte: the parser's
        f"   {ts} 1  7FF             Rx   d 2 01 02\r\n",  # CRLF
        f"   {t:.12f} 1  7FF             Rx   d 1 0A\n",  # more than 9 fraction digits
    ]
    return other[kind - 12].encode("latin-1")


def _log(seed: int, relative: bool) -> bytes:
    rng = np.random.default_rng(seed)
    head = [b"date Thu Apr 28 10:44:52.480 am 2022\n",
            f"base hex  timestamps {'relative' if relative else 'absolute'}\n".encode(),
            b"internal events logged\n", b"Begin Triggerblock Thu Apr 28 10:44:52.480 am 2022\n"]
    lines, t = [], 0.0
    for i in range(6000):
        t += float(rng.uniform(0, 0.002)) if not relative else 0.0
        dec = 3000 <= i < 3500
        if i == 3000:
            lines.append(f"base dec  timestamps {'relative' if relative else 'absolute'}\n".encode())
        if i == 3500:
            lines.append(f"base hex  timestamps {'relative' if relative else 'absolute'}\n".encode())
        lines.append(_line(rng, float(rng.uniform(0, 0.002)) if relative else t, dec))
    return b"".join(head + lines + [b"End TriggerBlock\n"])


Issues = list[tuple[str, int | None]]


def _read(data: bytes, scanner: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[FrameChunk, Issues]:
    monkeypatch.setattr(asc_module, "FAST_PATH_MIN_BYTES", 0 if scanner else 10**12)
    with open_log(io.BytesIO(data), chunk_frames=1000) as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    return chunk, [(i.kind, i.line) for i in log.report.issues]


@pytest.mark.parametrize("relative", [False, True], ids=["absolute", "relative"])
@pytest.mark.parametrize("seed", [1, 2])
def test_scanner_equals_line_parser_on_mixed_logs(seed: int, relative: bool, monkeypatch: pytest.MonkeyPatch) -> None:
    data = _log(seed, relative)
    fast, fast_issues = _read(data, True, monkeypatch)
    slow, slow_issues = _read(data, False, monkeypatch)
    assert len(fast) > 4000 and fast_issues == slow_issues and {k for k, _ in fast_issues} == {"non_hex", "bad_line"}
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc", "data"):
        a, b = getattr(fast, col), getattr(slow, col)
        assert a.shape == b.shape and (a == b).all(), col
    assert np.any(fast.flags & FrameFlag.FD) and np.any(fast.flags & FrameFlag.ERROR)
    assert np.any(fast.flags & FrameFlag.REMOTE) and np.any(fast.flags & FrameFlag.EXTENDED)
    if relative:
        assert (np.diff(fast.t_ns) >= 0).all()


def test_scanner_reads_the_fields_as_written() -> None:
    block = (b"   12.345678 2  18EBFF00x       Tx   d 3 01 A ff  Length = 1\n"
             b"\n"
             b"   0.000001 1  7FF             Rx   d 0\n"
             b"   1.5 1  100             Rx   d 2 01 02 03\n"
             b"   1.000000 1  123             Rx   d 2 100 11\n"
             b"   1.000000 1  FFFFFFFFx       Rx   d 0\n")
    scan = scan_block(block, True)
    assert scan.fast.tolist() == [True, False, True, True, False, False] and scan.blank.tolist()[1]
    assert scan.t_ns.tolist() == [12_345_678_000, 1_000, 1_500_000_000]
    assert scan.channel.tolist() == [1, 0, 0] and scan.arb_id.tolist() == [0x18EBFF00, 0x7FF, 0x100]
    assert scan.flags.tolist() == [int(FrameFlag.EXTENDED | FrameFlag.TX), 0, 0] and scan.dlc.tolist() == [3, 0, 2]
    assert scan.data[0, :3].tolist() == [1, 10, 255] and scan.data[2, :2].tolist() == [1, 2]
    assert not scan_block(block, False).fast.any()  # decimal base: every line is the parser's


@pytest.mark.parametrize("distinct", [1, 5, 24, 25, 300])
def test_group_rows_equals_a_stable_sort(distinct: int) -> None:
    rng = np.random.default_rng(distinct)
    key = rng.integers(0, distinct, 5000) * 7919
    order = np.argsort(key, kind="stable")
    got = group_rows(key)
    assert [k for k, _ in got] == sorted(set(key.tolist()))
    assert np.array_equal(np.concatenate([rows for _, rows in got]), order)
