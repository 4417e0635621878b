"""Replay and live analysis over real SocketCAN (vcan). Runs where the kernel has CAN sockets.

Set up with ``sudo scripts/setup-vcan.sh`` (channel from ``LASHSCOPE_VCAN``, default vcan0).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from app.errors import LiveBusError
from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink, can_sockets_available, open_bus
from app.live.decoding import source_for
from app.live.replay import Replayer
from app.live.session import LiveSession
from tests.live import drive

VCAN = os.environ.get("LASHSCOPE_VCAN", "vcan0")
AVAILABLE, REASON = can_sockets_available(VCAN)
needs_vcan = pytest.mark.skipif(not AVAILABLE, reason=f"SocketCAN not available: {REASON}")

pytestmark = pytest.mark.socketcan


@needs_vcan
def test_replay_into_live_session_over_vcan(tmp_path: Path) -> None:
    dbc = drive.write_dbc(tmp_path)
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=3.0))
    original = list(open_log(log).chunks())
    source = source_for(dbc, drive.map_of(dbc))[0]
    session = LiveSession(BusConfig("socketcan", VCAN), source, record_path=tmp_path / "rec.blf").start()
    link = BusLink(BusConfig("socketcan", VCAN))
    link.open()
    try:
        stats = Replayer(link, lambda: open_log(log).chunks()).run()
        assert session.wait_idle()
    finally:
        link.close()
        session.stop()
    assert stats.pacing.early == 0 and stats.frames_sent == sum(len(c) for c in original)
    assert drive.frames_of(list(open_log(tmp_path / "rec.blf").chunks())) == drive.frames_of(original)


@pytest.mark.skipif(AVAILABLE, reason="this machine has SocketCAN; the unavailable path is not reachable")
def test_without_can_sockets_opening_socketcan_says_why() -> None:
    with pytest.raises(LiveBusError, match="cannot open CAN bus socketcan:") as err:
        open_bus(BusConfig("socketcan", VCAN))
    assert REASON in str(err.value)
