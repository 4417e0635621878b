"""The TCU hex-stamped SD-card text log: shape, sniffing, salvage and strict modes, gzip."""

from __future__ import annotations

import gzip
import io
from pathlib import Path

import numpy as np
import pytest

from app.errors import LogFormatError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import open_log, sniff_format


def _tcu_lines(n: int = 300, seed: int = 7) -> tuple[list[str], list[tuple[int, int, bytes]]]:
    """Bursty frames of three extended IDs as the logger writes them: ms stamps in hex, 8 data bytes."""
    rng = np.random.default_rng(seed)
    t_ms, frames, lines = 0xB2, [], []
    ids = (0x0CFFAC01, 0x0CFFA501, 0x08580C02)
    for _ in range(n):
        t_ms += int(rng.choice([0, 1, 5, 59], p=[0.3, 0.3, 0.3, 0.1]))
        ident = int(rng.choice(ids))
        data = rng.integers(0, 256, 8, dtype=np.uint8).tobytes()
        frames.append((t_ms, ident, data))
        lines.append(f"{t_ms:08X}x{ident:08X}{data.hex().upper()}")
    return lines, frames


def _read(raw: bytes, name: str = "LOGS6.TXT", **kw: object) -> tuple[FrameChunk, object]:
    stream = io.BytesIO(raw)
    stream.name = name  # type: ignore[attr-defined]
    with open_log(stream, **kw) as log:  # type: ignore[arg-type]
        chunk = FrameChunk.concat(list(log.chunks()))
    return chunk, log


def test_frames_times_and_ids() -> None:
    lines, frames = _tcu_lines()
    raw = ("\n".join(lines) + "\n").encode()
    assert sniff_format(raw, "LOGS6.TXT") == "tcu"
    chunk, log = _read(raw)
    assert log.meta.format == "tcu" and log.meta.start_clock == "unknown"  # type: ignore[attr-defined]
    assert len(chunk) == len(frames) == 300
    t0 = frames[0][0]
    assert chunk.t_ns.tolist() == [(t - t0) * 1_000_000 for t, _, _ in frames]  # from the first frame, 1 ms per count
    assert log.meta.extra["clock_at_start_s"] == f"{t0 / 1000:g}"  # type: ignore[attr-defined]  # the logger clock there
    assert chunk.arb_id.tolist() == [i for _, i, _ in frames]
    assert np.all(chunk.flags == FrameFlag.EXTENDED) and np.all(chunk.dlc == 8) and np.all(chunk.channel == 0)
    assert [bytes(row) for row in chunk.data] == [d for _, _, d in frames]
    assert log.report.issues == []  # type: ignore[attr-defined]


def test_short_frames_and_crlf() -> None:
    chunk, _ = _read(b"0000000Ax0404FF01\r\n0000000Bx0404FF0201\r\n0000000Cx0404FF03A1B2C3\r\n")
    assert chunk.dlc.tolist() == [0, 1, 3]
    assert chunk.t_ns.tolist() == [0, 1_000_000, 2_000_000]  # 0x0A..0x0C ms, from the first frame
    assert chunk.data[2, :4].tolist() == [0xA1, 0xB2, 0xC3, 0]


def _damaged() -> bytes:
    lines, _ = _tcu_lines(20)
    lines[4] = lines[4][:9] + "0CFFZZ01" + lines[4][17:]  # garbled ID
    lines[9] = "\x00\x00\x00\x01garbage"                   # binary
    lines[12] = lines[12][:8] + lines[12][9:]               # no 'x'
    lines.append(lines[-1][:22])                            # cut by power loss: odd data digits
    return ("\n".join(lines) + "\n").encode("latin-1")


def test_salvage_reports_each_damaged_line() -> None:
    chunk, log = _read(_damaged())
    assert len(chunk) == 17
    issues = [(i.kind, i.line) for i in log.report.issues]  # type: ignore[attr-defined]
    assert issues == [("non_hex", 5), ("bad_line", 10), ("bad_line", 13), ("short_data", 21)]
    assert "odd number of hex digits" in log.report.issues[-1].message  # type: ignore[attr-defined]


def test_strict_stops_at_first_damaged_line() -> None:
    with pytest.raises(LogFormatError, match=r"LOGS6\.TXT: line skipped: identifier or data .* \(line 5\)"):
        _read(_damaged(), strict=True)


def test_gzip_and_file_path(tmp_path: Path) -> None:
    lines, frames = _tcu_lines(50)
    path = tmp_path / "LOGS7.TXT.gz"
    path.write_bytes(gzip.compress(("\n".join(lines) + "\n").encode()))
    with open_log(path) as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    assert log.meta.format == "tcu" and len(chunk) == 50
    assert chunk.t_ns[-1] == (frames[-1][0] - frames[0][0]) * 1_000_000


def test_id_wider_than_29_bits_is_reported() -> None:
    chunk, log = _read(b"00000001x2CFFAC010000000000000000\n00000002x0CFFAC010000000000000000\n")
    assert len(chunk) == 1
    assert [(i.kind, i.line) for i in log.report.issues] == [("bad_line", 1)]  # type: ignore[attr-defined]
