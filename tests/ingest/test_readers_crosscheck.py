"""Cross-check: every public log python-can 4.6 reads gives the same frames through our readers.

Compared per frame: time relative to the start (within 1 us), channel, arbitration ID,
extended / FD / error / remote / BRS / ESI / direction flags, DLC and data bytes. The only
normalisations are documented conventions: our channels are 0-based except TRC's, which
keep the file's 1-based bus number as python-can does (python-can's MF4 reader gives the
1-based bus number, its candump reader the interface name), and the
extended flag of an error frame without an ID is not compared (python-can defaults it to True).
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from app.ingest.frames import FrameChunk, FrameFlag, LogMeta
from app.ingest.readers import open_log
from tests.conftest import sample_files, sample_path

PYCAN = sample_path("python-can-testdata", "test", "data")  # all of python-can's vectors are committed
CROSS_FILES = (sample_files("python-can-testdata/test/data", "**/*.asc", "**/*.asc.gz", "**/*.blf", "**/*.trc")
               + sample_files("css-electronics-mf4", "**/*.MF4"))


def python_can_frames(path: Path) -> tuple[list[can.Message], float]:
    """python-can's messages and the absolute time it counts as the measurement start."""
    name = path.name.lower()
    if name.endswith(".blf"):
        with can.BLFReader(path) as blf:
            return list(blf), float(blf.start_timestamp)
    if name.endswith(".trc"):
        with can.TRCReader(path) as trc:
            return list(trc), float(trc._start_time or 0.0)
    if name.endswith(".mf4"):
        with can.MF4Reader(path) as mf4:
            return list(mf4), float(mf4._start_timestamp)
    with can.LogReader(path) as log:  # ASC (plain or gz): timestamps already relative to the start
        return list(log), 0.0


def our_channel_matches(fmt: str, meta: LogMeta, ours: int, theirs: object) -> bool:
    if fmt == "mf4":
        return ours + 1 == theirs
    if fmt == "candump":
        return meta.channels.get(ours) == theirs
    return ours == theirs


def assert_same_frames(fmt: str, meta: LogMeta, chunk: FrameChunk, msgs: list[can.Message], t_ref: float) -> None:
    """Frame-by-frame equality with python-can's messages (see the module docstring)."""
    assert len(chunk) == len(msgs), f"{len(chunk)} frames, python-can has {len(msgs)}"
    for i, m in enumerate(msgs):
        flags = int(chunk.flags[i])
        where = f"frame {i} ({m})"
        assert abs(int(chunk.t_ns[i]) / 1e9 - (m.timestamp - t_ref)) <= 1e-6, where
        assert our_channel_matches(fmt, meta, int(chunk.channel[i]), m.channel), f"channel {chunk.channel[i]}: {where}"
        assert bool(flags & FrameFlag.ERROR) == m.is_error_frame, where
        assert bool(flags & FrameFlag.REMOTE) == m.is_remote_frame, where
        assert bool(flags & FrameFlag.FD) == m.is_fd, where
        assert bool(flags & FrameFlag.BRS) == m.bitrate_switch, where
        assert bool(flags & FrameFlag.ESI) == m.error_state_indicator, where
        assert bool(flags & FrameFlag.TX) == (not m.is_rx), where
        if not (m.is_error_frame and fmt in ("asc", "candump")):
            assert int(chunk.arb_id[i]) == m.arbitration_id, where
            assert bool(flags & FrameFlag.EXTENDED) == m.is_extended_id, where
        assert int(chunk.dlc[i]) == m.dlc, where
        n = min(int(chunk.dlc[i]), chunk.width)
        payload = b"" if m.is_remote_frame else bytes(chunk.data[i, :n])
        assert payload == bytes(m.data), where


@pytest.mark.parametrize("path", CROSS_FILES, ids=lambda p: p.name)
def test_same_frames_as_python_can(path: Path) -> None:
    msgs, t_ref = python_can_frames(path)
    with open_log(path) as log:
        chunk = FrameChunk.concat(log.chunks())
        fmt, meta, report = log.meta.format, log.meta, log.report
    assert report.frames == len(chunk)
    assert [i for i in report.issues if i.kind not in ("time_backwards",)] == []
    assert_same_frames(fmt, meta, chunk, msgs, t_ref)


def test_cross_check_covers_every_python_can_vector() -> None:
    if not PYCAN.is_dir():
        pytest.skip(f"public sample data not found: {PYCAN}")
    logs = {p.name for p in PYCAN.iterdir() if p.suffix != ".json"}
    assert logs == {p.name for p in CROSS_FILES if p.parent == PYCAN}
    assert len(logs) >= 24


@pytest.mark.parametrize("chunk_frames", [1, 3, 1000])
def test_chunking_does_not_change_frames(chunk_frames: int) -> None:
    path = PYCAN / "issue_1256.asc"
    if not path.exists():
        pytest.skip(f"public sample data not found: {path}")
    with open_log(path) as whole:
        ref = FrameChunk.concat(whole.chunks())
    with open_log(path, chunk_frames=chunk_frames) as log:
        parts = list(log.chunks())
    assert all(len(p) <= chunk_frames for p in parts)
    got = FrameChunk.concat(parts)
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc", "data"):
        assert (getattr(got, col) == getattr(ref, col)).all(), col
