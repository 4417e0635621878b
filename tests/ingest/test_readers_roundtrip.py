"""Round trips: logs written by python-can's writers read back equal to the messages written.

The messages are generated with a fixed seed and cover standard and extended IDs, every
classic length, remote frames, error frames, CAN FD with every FD length up to 64 bytes
and BRS/ESI, two channels and both directions (each writer gets what its format can hold).
"""

from __future__ import annotations

import gzip
import io
from datetime import UTC, datetime
from pathlib import Path

import can
import numpy as np
import pytest

from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import LogReader, open_log
from app.ingest.readers.asc import parse_asc_date
from tests.ingest.test_readers_crosscheck import assert_same_frames

FD_LENGTHS = (0, 1, 5, 8, 12, 16, 20, 24, 32, 48, 64)
T0 = 1_700_000_000.25


def make_messages(n: int, *, fd: bool, remote: bool, errors: bool, channels: tuple[object, ...] = (0, 1),
                  seed: int = 7) -> list[can.Message]:
    """A deterministic mix of frames with microsecond timestamps (what text formats can hold)."""
    rng = np.random.default_rng(seed)
    kinds = ["classic"] + ["fd"] * fd + ["remote"] * remote + ["error"] * errors
    t_us = 0
    msgs = []
    for i in range(n):
        t_us += int(rng.integers(1, 5000))
        kind = kinds[i % len(kinds)]
        ext = bool(rng.integers(0, 2))
        ident = int(rng.integers(0, 0x1FFFFFFF if ext else 0x7FF))
        common = {"timestamp": T0 + t_us / 1e6, "channel": channels[i % len(channels)],
                  "is_extended_id": ext, "arbitration_id": ident}
        if kind == "classic":
            data = rng.integers(0, 256, int(rng.integers(0, 9)), dtype=np.uint8).tobytes()
            msgs.append(can.Message(data=data, is_rx=bool(rng.integers(0, 2)), **common))
        elif kind == "fd":
            size = FD_LENGTHS[i % len(FD_LENGTHS)]
            data = rng.integers(0, 256, size, dtype=np.uint8).tobytes()
            msgs.append(can.Message(data=data, is_fd=True, bitrate_switch=bool(i % 2), error_state_indicator=i % 3 == 0,
                                    is_rx=bool(rng.integers(0, 2)), **common))
        elif kind == "remote":
            msgs.append(can.Message(is_remote_frame=True, dlc=int(rng.integers(0, 9)), **common))
        else:
            msgs.append(can.Message(is_error_frame=True, timestamp=common["timestamp"], channel=common["channel"],
                                    arbitration_id=0, is_extended_id=False, dlc=0))
    return msgs


def read_back(path: Path) -> tuple[FrameChunk, LogReader]:
    with open_log(path) as log:
        chunk = FrameChunk.concat(log.chunks())
    assert log.report.frames == len(chunk)
    assert [i for i in log.report.issues if i.kind != "time_backwards"] == []
    return chunk, log


@pytest.mark.parametrize("compression_level", [-1, 0], ids=["zlib", "uncompressed"])
@pytest.mark.parametrize("container", [128 * 1024, 1000], ids=["128k-containers", "1k-containers"])
def test_blf_writer_round_trip(tmp_path: Path, compression_level: int, container: int) -> None:
    msgs = make_messages(3000, fd=True, remote=True, errors=True)
    path = tmp_path / "rt.blf"
    with can.BLFWriter(path, compression_level=compression_level, max_container_size=container) as w:
        for m in msgs:
            w.on_message_received(m)
    chunk, log = read_back(path)
    start = int(msgs[0].timestamp * 1000) / 1000  # the writer truncates its start time to ms
    assert_same_frames("blf", log.meta, chunk, msgs, start)
    assert chunk.width == 64
    # python-can writes the UTC wall time into the header field that Vector tools fill with local time
    assert log.meta.start_clock == "blf_header_local"
    assert log.meta.start_time == datetime.fromtimestamp(start, UTC).replace(tzinfo=None)


def test_asc_writer_round_trip(tmp_path: Path) -> None:
    msgs = make_messages(2000, fd=True, remote=True, errors=True)
    path = tmp_path / "rt.asc"
    with can.ASCWriter(path) as w:
        for m in msgs:
            w.on_message_received(m)
    chunk, log = read_back(path)
    assert_same_frames("asc", log.meta, chunk, msgs, msgs[0].timestamp)
    assert log.meta.start_clock == "asc_date_header_local"
    # python-can's writer puts the file's creation time into "date" and counts its timestamps from
    # the "Begin Triggerblock" time, which the reader keeps in meta.extra
    trigger = parse_asc_date(log.meta.extra["triggerblock"])
    assert trigger is not None and trigger[1] == "asc_date_header_local"
    assert abs((trigger[0] - datetime.fromtimestamp(msgs[0].timestamp)).total_seconds()) < 1e-3


def test_asc_gzip_round_trip_by_content(tmp_path: Path) -> None:
    msgs = make_messages(500, fd=True, remote=True, errors=True)
    plain = tmp_path / "rt.asc"
    with can.ASCWriter(plain) as w:
        for m in msgs:
            w.on_message_received(m)
    packed = gzip.compress(plain.read_bytes())
    for name in ("rt.asc.gz", "misnamed.bin"):
        (tmp_path / name).write_bytes(packed)
        chunk, log = read_back(tmp_path / name)
        assert log.meta.format == "asc"
        assert_same_frames("asc", log.meta, chunk, msgs, msgs[0].timestamp)
    # a caller's (non-seekable) stream works as well
    with open_log(_NonSeekable(packed)) as log:
        assert len(FrameChunk.concat(log.chunks())) == len(msgs)


class _NonSeekable(io.RawIOBase):
    def __init__(self, data: bytes) -> None:
        self._buf = io.BytesIO(data)

    def readable(self) -> bool:
        return True

    def readinto(self, b: bytearray) -> int:  # type: ignore[override]
        data = self._buf.read(len(b))
        b[: len(data)] = data
        return len(data)


def test_canutils_writer_round_trip(tmp_path: Path) -> None:
    msgs = make_messages(2000, fd=True, remote=True, errors=False, channels=("can0", "vcan1"))
    for m in msgs:
        if m.is_remote_frame:
            m.dlc = 0  # the writer writes "R" without the DLC
    path = tmp_path / "rt.log"
    with can.CanutilsLogWriter(path) as w:
        for m in msgs:
            w.on_message_received(m)
    chunk, log = read_back(path)
    assert_same_frames("candump", log.meta, chunk, msgs, msgs[0].timestamp)
    assert log.meta.channels == {0: "can0", 1: "vcan1"}
    assert log.meta.start_clock == "epoch_utc"
    assert log.meta.start_time == datetime.fromtimestamp(round(msgs[0].timestamp, 6), UTC)


def test_trc_writer_round_trip(tmp_path: Path) -> None:
    msgs = make_messages(2000, fd=False, remote=False, errors=False)  # python-can's TRCWriter: classic only
    path = tmp_path / "rt.trc"
    with can.TRCWriter(path) as w:
        for m in msgs:
            w.on_message_received(m)
    chunk, log = read_back(path)
    shifted = [can.Message(timestamp=m.timestamp, arbitration_id=m.arbitration_id, is_extended_id=m.is_extended_id,
                           data=m.data, is_rx=m.is_rx, channel=int(m.channel) + 1) for m in msgs]  # type: ignore[arg-type]
    assert_same_frames("trc", log.meta, chunk, shifted, msgs[0].timestamp)
    assert log.meta.start_clock == "trc_header_local"


def test_candump_error_frame_keeps_error_class() -> None:
    text = b"(1700000000.000100) can0 20000080#0000000000000000\n(1700000000.000200) can0 123#R3 T\n"
    with open_log(io.BytesIO(text)) as log:
        chunk = FrameChunk.concat(log.chunks())
    assert log.meta.format == "candump"
    assert chunk.flags[0] == FrameFlag.ERROR and chunk.arb_id[0] == 0x80 and chunk.dlc[0] == 8
    assert chunk.flags[1] == FrameFlag.REMOTE | FrameFlag.TX and chunk.dlc[1] == 3 and chunk.t_ns[1] == 100_000
