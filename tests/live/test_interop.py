"""python-can's own tools as peers: our recordings through its reader and player; its logger's files through ours."""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import can
import numpy as np
import pytest

from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink
from app.live.decoding import source_for
from app.live.replay import Replayer
from app.live.session import LiveSession
from tests.live import drive


def _record(tmp_path: Path, log: Path, dbc: Path, channel: str, name: str, rate: float = 1.0) -> LiveSession:
    source = source_for(dbc, drive.map_of(dbc))[0]
    session = LiveSession(BusConfig("virtual", channel), source, record_path=tmp_path / name).start()
    link = BusLink(BusConfig("virtual", channel))
    link.open()
    try:
        Replayer(link, lambda: open_log(log).chunks(), rate=rate).run()
        assert session.wait_idle()
    finally:
        link.close()
        session.stop()
    return session


def _py_frames(msgs: list[can.Message]) -> list[tuple[int, bool, bool, bool, bytes]]:
    # an error frame's "ID" is error-class bits that formats and readers encode differently
    return [(0, False, True, False, b"") if m.is_error_frame else
            (m.arbitration_id, m.is_extended_id, False, m.is_remote_frame, bytes(m.data)) for m in msgs]


def _ours(chunks: list) -> list[tuple[int, int, int, bytes]]:
    return [(0, 4, 0, b"") if f & 4 else (a, f, n, p) for a, f, n, p in drive.frames_of(chunks)]


def test_recording_read_by_python_can_and_played_by_can_player(tmp_path: Path,
                                                                monkeypatch: pytest.MonkeyPatch) -> None:
    dbc = drive.write_dbc(tmp_path)
    msgs = drive.drive_messages(duration_s=2.0, error_frames=2)
    log = drive.write_blf(tmp_path / "drive.blf", msgs)
    _record(tmp_path, log, dbc, "interop-rec", "rec.blf", rate=4.0)

    # python-can's reader reads our recording back, frame for frame
    with can.LogReader(str(tmp_path / "rec.blf")) as reader:
        back = list(reader)
    assert _py_frames(back) == _py_frames(msgs)

    # can.player (its command-line entry point, run in this process so the virtual bus is shared)
    # plays our recording into a live session, error frames included
    source = source_for(dbc, drive.map_of(dbc))[0]
    listener = LiveSession(BusConfig("virtual", "interop-play"), source, record_path=tmp_path / "played.blf").start()
    monkeypatch.setattr(sys, "argv", ["can.player", "-i", "virtual", "-c", "interop-play", "--error-frames",
                                      str(tmp_path / "rec.blf")])
    from can.player import main as player_main

    player = threading.Thread(target=player_main)
    player.start()
    player.join(30)
    assert not player.is_alive()
    try:
        assert listener.wait_idle()
    finally:
        listener.stop()
    st = listener.status()
    assert st["frames_received"] == len(msgs) and st["bus_errors"] == 2
    with can.LogReader(str(tmp_path / "played.blf")) as reader:
        assert _py_frames(list(reader)) == _py_frames(msgs)


@pytest.mark.parametrize("suffix", [".asc", ".blf", ".log", ".trc"])
def test_files_written_by_can_logger_are_ingested(tmp_path: Path, suffix: str) -> None:
    msgs = drive.drive_messages(duration_s=1.0, error_frames=1)
    log = drive.write_blf(tmp_path / "drive.blf", msgs)
    out = tmp_path / f"logged{suffix}"
    rx = can.Bus(interface="virtual", channel=f"interop-log{suffix}")
    writer = can.Logger(str(out))  # what `python -m can.logger -f FILE` writes with
    notifier = can.Notifier(rx, [writer])
    link = BusLink(BusConfig("virtual", f"interop-log{suffix}"))
    link.open()
    try:
        Replayer(link, lambda: open_log(log).chunks(), rate=5.0).run()
        deadline = threading.Event()
        deadline.wait(0.3)
    finally:
        link.close()
        notifier.stop()  # stops (closes) the writer too
        rx.shutdown()
    with open_log(out) as reader:
        chunks = list(reader.chunks())
        assert reader.report.ok, reader.report.issues
    theirs, ours = _ours(chunks), _ours(list(open_log(log).chunks()))
    if suffix == ".trc":  # python-can's TRC writer drops error frames ("not implemented")
        ours = [f for f in ours if not f[1] & 4]
    assert theirs == ours
    t = drive.times_of(chunks)
    assert np.all(np.diff(t) >= 0)
    assert (t[-1] - t[0]) / 1e9 == pytest.approx((msgs[-1].timestamp - msgs[0].timestamp) / 5.0, abs=0.05)
