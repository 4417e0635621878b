"""BLF recording that survives an abrupt stop: kill the recording process, read the file back."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import can
import pytest

from app.live.loopback import LoopbackBus, LoopbackHub
from app.live.recorder import FlushingBLFWriter

REPO = Path(__file__).resolve().parents[2]

CHILD = r"""
import sys, time, can
from app.live.loopback import LoopbackBus
from app.live.recorder import FlushingBLFWriter
channel, path, plain = sys.argv[1], sys.argv[2], sys.argv[3] == "plain"
bus = LoopbackBus(channel)
w = can.BLFWriter(path) if plain else FlushingBLFWriter(path, time.time())
print("ready", flush=True)
while True:
    m = bus.recv(0.05)
    if m is not None:
        w.on_message_received(m)
    if not plain:
        w.tick()
"""


def _frame(i: int) -> can.Message:
    return can.Message(arbitration_id=0x100 + i % 7, data=i.to_bytes(4, "little") + b"\xaa\xbb\xcc\xdd",
                       is_extended_id=False)


def _start_child(channel: str, path: Path, mode: str) -> subprocess.Popen[str]:
    proc = subprocess.Popen([sys.executable, "-c", CHILD, channel, str(path), mode], cwd=REPO,
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    assert proc.stdout.readline().strip() == "ready"
    return proc


def test_killed_recording_keeps_all_but_the_last_second(tmp_path: Path) -> None:
    flushing, plain = tmp_path / "flushing.blf", tmp_path / "plain.blf"
    with LoopbackHub() as hub:
        procs = [_start_child(hub.channel, flushing, "flushing"), _start_child(hub.channel, plain, "plain")]
        t_start = time.time()
        sender = LoopbackBus(hub.channel)
        sent: list[tuple[float, can.Message]] = []
        try:
            # 200 frames/s for 2.5 s: a low bus load, where python-can's 128 KiB containers would take minutes
            for i in range(500):
                due = t_start + i / 200
                time.sleep(max(0.0, due - time.time()))
                m = _frame(i)
                sender.send(m)
                sent.append((time.time(), m))
            t_kill = time.time()
            for p in procs:
                os.kill(p.pid, signal.SIGKILL)
                p.wait(5)
        finally:
            sender.shutdown()
            for p in procs:
                if p.poll() is None:
                    p.kill()
                if p.stdout is not None:
                    p.stdout.close()

    with can.BLFReader(str(flushing)) as reader:
        got = list(reader)
        start = reader.start_timestamp
    must_have = sum(1 for t, _ in sent if t < t_kill - 1.0)
    assert len(got) >= must_have > 250
    assert [(m.arbitration_id, bytes(m.data)) for m in got] == \
        [(m.arbitration_id, bytes(m.data)) for _, m in sent[: len(got)]]
    # the start time was written up front, so a cut-off file still has its absolute times
    assert abs(start - t_start) < 5.0
    assert abs(got[0].timestamp - sent[0][0]) < 0.5

    # the same traffic through python-can's writer, killed alike, kept no frame (not even its header)
    assert plain.stat().st_size == 0


def test_clean_stop_writes_a_complete_file_python_can_reads(tmp_path: Path) -> None:
    path = tmp_path / "clean.blf"
    t0 = time.time()
    w = FlushingBLFWriter(path, t0, flush_interval_s=0.01)
    frames = [_frame(i) for i in range(50)]
    frames += [can.Message(arbitration_id=0x18DAF110, is_fd=True, bitrate_switch=True, data=bytes(range(64))),
               can.Message(arbitration_id=0x123, is_remote_frame=True, dlc=3, is_extended_id=False),
               can.Message(arbitration_id=0x0, is_error_frame=True, is_extended_id=False)]
    for k, m in enumerate(frames):
        m.timestamp = t0 + 0.01 * k
        w.on_message_received(m)
        if k % 10 == 0:
            time.sleep(0.012)
            w.tick()
    w.stop()
    with can.BLFReader(str(path)) as reader:
        got = list(reader)
        assert reader.object_count == len(frames)
    assert len(got) == len(frames)
    for a, b in zip(got, frames, strict=True):
        assert (a.arbitration_id, a.is_fd, a.is_remote_frame, a.is_error_frame, a.dlc) == \
            (b.arbitration_id, b.is_fd, b.is_remote_frame, b.is_error_frame, b.dlc)
        if not (b.is_remote_frame or b.is_error_frame):
            assert bytes(a.data) == bytes(b.data)
        assert a.timestamp == pytest.approx(b.timestamp, abs=2e-3)
