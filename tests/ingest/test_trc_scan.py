"""The vectorised TRC scanner against the line parser, in every file version.

Generated logs (fixed seeds) interleave lines of the scanner's shape (classic frames of every
width, standard and extended IDs, Tx, 1-digit bytes, whole-millisecond offsets, trailing text)
with lines only the parser reads (remote, error, status and CAN FD lines, comments, blank
lines, damaged lines, control bytes, CRLF, a bus number out of range). Each is read twice, once
with the scanner and once line by line, and must give the same frames, issues and line numbers;
spot values are checked against what the lines say, and the scanner must take most lines.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import open_log
from app.ingest.readers import trc as trc_module
from app.ingest.readers.trc_scan import Layout, scan_block
from tests.conftest import sample_files

HEADERS = {
    "1.0": ";##########\n;   Start time: 18.12.2021 14:28:07.062\n;##########\n",
    "1.1": ";$FILEVERSION=1.1\n;$STARTTIME=44548.6028595139\n",
    "1.2": ";$FILEVERSION=1.2\n;$STARTTIME=44548.6028595139\n",
    "1.3": ";$FILEVERSION=1.3\n;$STARTTIME=44548.6028595139\n",
    "2.0": ";$FILEVERSION=2.0\n;$STARTTIME=44548.6028595139\n;$COLUMNS=N,O,T,B,I,d,l,D\n",
    "2.1": ";$FILEVERSION=2.1\n;$STARTTIME=44548.6028595139\n;$COLUMNS=N,O,T,B,I,d,R,L,D\n",
    "2.1nob": ";$FILEVERSION=2.1\n;$STARTTIME=44548.6028595139\n;$COLUMNS=N,O,T,I,d,L,D\n",
}


def _frame(version: str, n: int, ms: str, bus: int, kind: str, ident: str, dlc: str, data: str) -> str:
    if version == "1.0":
        return f"{n:6d}) {ms:>11} {ident:>8}  {dlc}  {data}\n"
    if version == "1.1":
        return f"{n:6d}) {ms:>11}  {kind}  {ident:>8}  {dlc}  {data}\n"
    if version == "1.2":
        return f"{n:6d}) {ms:>11} {bus}  {kind}  {ident:>8}  {dlc}  {data}\n"
    if version == "1.3":
        return f"{n:6d}) {ms:>11} {bus}  {kind}  {ident:>8} -  {dlc}  {data}\n"
    t = "DT" if kind in ("Rx", "Tx") else kind
    if version == "2.1nob":
        return f"{n:7d} {ms:>13} {t} {ident:>8} {kind if t == 'DT' else 'Rx'} {dlc}  {data}\n"
    reserved = " -" if version == "2.1" else ""
    return f"{n:7d} {ms:>13} {t} {bus} {ident:>8} {kind if t == 'DT' else 'Rx'}{reserved} {dlc}  {data}\n"


def _line(rng: np.random.Generator, version: str, n: int, t_ms: float) -> str:
    kind = int(rng.integers(0, 100))
    ms = f"{t_ms:.3f}" if kind % 10 != 3 else f"{int(t_ms)}"
    bus = int(rng.integers(1, 4))
    if kind < 89:  # the scanner's shape, in its variants (other lines 1 in 9, so the report keeps every issue)
        kind %= 10
        width = int(rng.integers(0, 9))
        ident = f"{rng.integers(0, 0x1FFFFFFF):08X}" if kind % 3 == 0 else f"{rng.integers(0, 0x800):04X}"
        data = " ".join(f"{b:X}" if kind == 5 else f"{b:02X}" for b in rng.integers(0, 256, width))
        tail = "  trailing text" if kind == 7 and version.startswith("1") else ""
        return _frame(version, n, ms, bus, "Tx" if kind == 4 else "Rx", ident, str(width), data) + tail
    v2 = version.startswith("2")
    other = [
        _frame(version, n, ms, bus, "RR" if v2 else "Rx", "0123", "4", "" if v2 else "RTR"),
        _frame(version, n, ms, bus, "ER" if v2 else "Error", "0000", "0", ""),
        _frame(version, n, ms, bus, "ST" if v2 else "Warng", "FFFFFFFF", "4", "00 00 00 08"),
        _frame(version, n, ms, bus, "FD" if v2 else "Rx", "0456", "12" if v2 else "9", " ".join(["AB"] * 24)),
        ";   a comment 1) 2.0 Rx 0123 1 00\n",
        "\n",
        _frame(version, n, ms, bus, "Rx", "0123", "8", "00 11 22 ZZ 44 55 66 77"),  # damaged: non_hex
        _frame(version, n, ms, bus, "Rx", "0123", "2", "01\x07 02"),  # control byte: the parser's
        _frame(version, n, ms, bus, "Rx", "07FF", "2", "01 02").replace("\n", "\r\n"),  # CRLF
        _frame(version, n, ms, 40000, "Rx", "07FF", "1", "0A"),  # bus number out of range (where there is one)
        _frame(version, n, f"{t_ms:.9f}", bus, "Rx", "07FF", "1", "0A"),  # fraction digits past 1 ns
    ]
    return other[kind - 89]


def _log(seed: int, version: str) -> bytes:
    rng = np.random.default_rng(seed)
    lines, t = [HEADERS[version]], 0.0
    for n in range(1, 6001):
        t += float(rng.uniform(0, 2.0))
        lines.append(_line(rng, version, n, t))
    return "".join(lines).encode("latin-1")


Issues = list[tuple[str, int | None]]


def _read(data: bytes, scanner: bool, monkeypatch: pytest.MonkeyPatch) -> tuple[FrameChunk, Issues]:
    monkeypatch.setattr(trc_module, "FAST_PATH_MIN_BYTES", 0 if scanner else 10**12)
    with open_log(io.BytesIO(data), chunk_frames=1000) as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    # by kind: a block's line issues are reported before the chunk checks (time order) of the frames read with them
    return chunk, sorted(((i.kind, i.line) for i in log.report.issues), key=lambda k: (k[0], k[1] or 0))


def _same(fast: FrameChunk, slow: FrameChunk) -> None:
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc", "data"):
        a, b = getattr(fast, col), getattr(slow, col)
        assert a.shape == b.shape and (a == b).all(), col


@pytest.mark.parametrize("version", list(HEADERS))
def test_scanner_equals_line_parser_on_mixed_logs(version: str, monkeypatch: pytest.MonkeyPatch) -> None:
    data = _log(7, version)
    fast, fast_issues = _read(data, True, monkeypatch)
    slow, slow_issues = _read(data, False, monkeypatch)
    assert len(fast) > 5000 and fast_issues == slow_issues and "non_hex" in {k for k, _ in fast_issues}
    _same(fast, slow)
    assert np.any(fast.flags & FrameFlag.EXTENDED) and np.any(fast.flags & FrameFlag.REMOTE)
    if version != "1.0":  # 1.0 has no direction column and no error lines
        assert np.any(fast.flags & FrameFlag.ERROR) and np.any(fast.flags & FrameFlag.TX)
    layout = Layout(version[:3], _columns(data))
    _, taken, _, _ = scan_block(data, layout)
    assert taken.sum() > 0.8 * taken.size  # the scanner, not the parser, read most lines


def _columns(data: bytes) -> dict[str, int]:
    for line in data.decode("latin-1").splitlines():
        if line.startswith(";$COLUMNS="):
            return {c: i for i, c in enumerate(line.split("=", 1)[1].split(","))}
    return {}


def test_scanner_reads_the_fields_as_written() -> None:
    block = (b"     1)     17535.400 2  Tx    18EBFF00 -  3    01 A ff trailing\n"
             b"\n"
             b"     2)     17540 1  Rx    07FF -  0\n"
             b"     3)     17541.3 1  Rx    0100 -  2    01 02 03\n"
             b"     4)     17541.3 1  Rx    0100 -  2    100 11\n"
             b";    5)     17541.3 1  Rx    0100 -  0\n"
             b"     6)     17541.3 1  Rx    0100 -  0 RTR\n")
    _, fast, (t_ns, channel, ident, flags, dlc), data = scan_block(block, Layout("1.3", {}))
    assert fast.tolist() == [True, False, True, True, False, False, False]
    assert t_ns.tolist() == [17_535_400_000, 17_540_000_000, 17_541_300_000]
    assert channel.tolist() == [2, 1, 1] and ident.tolist() == [0x18EBFF00, 0x7FF, 0x100]
    assert flags.tolist() == [int(FrameFlag.EXTENDED | FrameFlag.TX), 0, 0] and dlc.tolist() == [3, 0, 2]
    assert data[0, :3].tolist() == [1, 10, 255] and data[2, :2].tolist() == [1, 2]
    v2 = b"      1     17535.400 DT 1  00000100 Tx -  12    " + b"00 " * 8 + b"\n"
    _, fast, (_, _, _, flags, dlc), _ = scan_block(v2, Layout("2.1", {c: i for i, c in enumerate("NOTBIdRLD")}))
    assert fast.tolist() == [True] and dlc.tolist() == [8]
    assert flags.tolist() == [int(FrameFlag.EXTENDED | FrameFlag.TX)]


TRC_FILES = sample_files("", "**/*.trc")


@pytest.mark.parametrize("path", TRC_FILES, ids=lambda p: p.name[:40])
def test_scanner_equals_line_parser_on_sample_files(path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = path.read_bytes()
    fast, fast_issues = _read(data, True, monkeypatch)
    slow, slow_issues = _read(data, False, monkeypatch)
    assert fast_issues == slow_issues and len(fast) == len(slow) > 0
    _same(fast, slow)


@pytest.mark.parametrize(("version", "shown"), [("1.1", "1.1"), ("1.2", "1.2"), ("1.3", "1.3"), ("1.0", None)])
def test_a_file_without_its_version_line_is_read_by_its_lines_shape(version: str, shown: str | None) -> None:
    body = "".join(_frame(version, n, f"{n * 10}.5", 2, "Tx", "0123", "2", "0A 0B") for n in range(1, 4))
    with open_log(io.BytesIO(body.encode()), fmt="trc") as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    assert log.report.ok and len(chunk) == 3 and chunk.arb_id.tolist() == [0x123] * 3
    assert chunk.t_ns.tolist() == [10_500_000, 20_500_000, 30_500_000] and bytes(chunk.data[0, :2]) == b"\n\x0b"
    assert log.meta.extra["trc_version"] == (shown or "1.0")
    assert log.meta.extra.get("trc_version_from") == (None if shown is None else "line shape (no $FILEVERSION)")
    if version in ("1.2", "1.3"):
        assert chunk.channel.tolist() == [2] * 3
    if shown is not None:
        assert (chunk.flags & FrameFlag.TX).all()
