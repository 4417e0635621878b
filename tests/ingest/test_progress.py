"""Readers report how far they are: ``position()`` of ``size`` bytes, for files, gzip, in-memory streams and pipes."""

from __future__ import annotations

import gzip
import io
import os
import random
from pathlib import Path

import pytest

from app.ingest.readers import LogReader, open_log
from tests.conftest import sample_files


def candump(n: int) -> bytes:
    rnd = random.Random(5)
    return b"".join(f"({1700000000 + i / 1000:.6f}) can0 {0x100 + i % 7:03X}#{rnd.randbytes(8).hex().upper()}\n"
                    .encode() for i in range(n))


def walk(reader: LogReader) -> list[int | None]:
    """Positions after opening and after each chunk."""
    seen = [reader.position()]
    for _ in reader.chunks():
        seen.append(reader.position())
    return seen


@pytest.mark.parametrize("compress", [False, True])
def test_file_positions_rise_to_the_size(tmp_path: Path, compress: bool) -> None:
    raw = candump(100_000)  # ~4.6 MB: readers take 1 MiB blocks
    path = tmp_path / ("log.log.gz" if compress else "log.log")
    path.write_bytes(gzip.compress(raw) if compress else raw)
    with open_log(path, chunk_frames=4096) as reader:
        assert reader.size == path.stat().st_size  # the stored (compressed) bytes
        seen = walk(reader)
    assert all(isinstance(p, int) for p in seen)
    pos = [p for p in seen if p is not None]
    assert pos == sorted(pos) and len(set(pos)) >= (3 if compress else 5)  # grows as blocks are read
    assert pos[-1] == reader.size
    assert 0 < pos[len(pos) // 2] < reader.size  # halfway is somewhere in the middle


def test_in_memory_stream_after_an_offset() -> None:
    raw = candump(5000)
    buf = io.BytesIO(b"JUNK" + raw)
    buf.seek(4)  # the log starts here: size and position count from its first byte
    reader = open_log(buf, chunk_frames=1000)
    assert reader.size == len(raw)
    assert walk(reader)[-1] == len(raw)


def test_pipe_has_no_size() -> None:
    r, w = os.pipe()
    os.write(w, candump(200))
    os.close(w)
    with os.fdopen(r, "rb") as pipe:
        reader = open_log(pipe)
        assert reader.size is None
        seen = walk(reader)
    assert seen[-1] is not None and seen[-1] > 0  # bytes consumed are still known


def test_mf4_position_from_records() -> None:
    path = next(iter(sample_files("css-electronics-mf4", "**/*.MF4")), None)
    if path is None:
        pytest.skip("no MF4 file in the shared data")
    with open_log(path, chunk_frames=2000) as reader:
        seen = walk(reader)
        assert reader.size == path.stat().st_size
    assert seen[0] == 0 and seen[-1] == reader.size and seen == sorted(seen)


def test_load_signals_progress_uses_the_public_position(tmp_path: Path) -> None:
    import cantools

    from app.ingest.database import LoadedDatabase
    from app.ingest.pipeline_signals import load_signals
    from app.ingest.signalmap import parse_signal_map

    db = cantools.database.load_string(
        'VERSION ""\nNS_ :\nBS_:\nBU_: A\nBO_ 256 Speed: 8 A\n SG_ Rpm : 0|16@1+ (1,0) [0|65535] "rpm" A\n', "dbc")
    smap = parse_signal_map({"channels": {"motor_speed_rpm": {"message": "Speed", "signal": "Rpm"}}})
    log = tmp_path / "speed.log"
    log.write_bytes(b"".join(f"({1700000000 + i / 1000:.6f}) can0 100#{i % 65536:04X}000000000000\n".encode()
                             for i in range(100_000)))  # ~4 MB
    fractions: list[float] = []
    signals, _ = load_signals(log, LoadedDatabase(db, log, "dbc"), smap,
                              progress=lambda f, _frames: fractions.append(f), chunk_frames=4096)
    assert len(signals["motor_speed_rpm"]) == 100_000
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert len({f for f in fractions if 0.0 < f < 1.0}) >= 2  # progress moves while reading, not only at the end
