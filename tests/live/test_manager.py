"""Live sessions of the service: vehicle decoding with events, the stored log and its analysis, crash recovery."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from app.errors import ConflictError, InputError
from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink
from app.live.decoding import source_for
from app.live.manager import LiveManager, StartRequest
from app.live.recorder import FlushingBLFWriter
from app.live.replay import Replayer
from app.storage.sqlstore import SQLStore
from app.storage.url import open_store
from tests.conftest import REPO, new_store_url
from tests.live import drive


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[SQLStore]:
    """A store on each backend, its files in ``tmp_path / "data"``."""
    s = open_store(new_store_url(request, request.param, tmp_path / "data"))
    yield s
    s.close()


def test_session_with_a_vehicle_becomes_a_stored_log_with_an_analysis(tmp_path: Path, store: SQLStore) -> None:
    dbc = drive.write_dbc(tmp_path)
    store.add_vehicle("testcar", driveline=REPO / "sim" / "presets" / "paper.toml", database=dbc,
                      signal_map=drive.map_of(dbc), summary={})
    submitted: list[str] = []
    manager = LiveManager(store, tmp_path / "data" / "live", source_for, submit=submitted.append,
                          max_sessions=1)
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=4.0, period_s=1.6))
    session = manager.start(StartRequest(BusConfig("virtual", "mgr"), vehicle="testcar"))
    with pytest.raises(ConflictError, match="limit 1"):
        manager.start(StartRequest(BusConfig("virtual", "mgr2"), vehicle="testcar"))
    link = BusLink(BusConfig("virtual", "mgr"))
    link.open()
    try:
        Replayer(link, lambda: open_log(log).chunks(), rate=2.0).run()
        assert session.wait_idle()
    finally:
        link.close()
    done = manager.stop(session.id)
    assert manager.stop(session.id) == done  # idempotent
    assert [e["kind"] for e in session.events] == ["tip_in", "tip_out"]
    # the vehicle's rotor inertia reaches the live metrics, so the free-rotor gap-open time is estimated
    assert session.analyzer is not None and session.analyzer.metric_params is not None
    assert session.analyzer.metric_params.free_rotor_inertia_kgm2 is not None
    assert session.analyzer.metric_params.free_rotor_inertia_kgm2 > 0.01
    rec = store.get_log(done.log_id)
    assert rec.frames == session.counters.frames_processed and rec.meta["source"] == "live"
    analysis = store.get_analysis(done.analysis_id)
    assert analysis.vehicle_name == "testcar" and submitted == [analysis.job.id]
    assert not list((tmp_path / "data" / "live").glob("*.blf"))  # moved into the store


def test_interfaces_reaching_the_network_are_off_by_default(tmp_path: Path, store: SQLStore) -> None:
    manager = LiveManager(store, tmp_path / "live", source_for)
    for name in ("udp_multicast", "socketcand"):
        with pytest.raises(InputError, match="not enabled"):
            manager.start(StartRequest(BusConfig(name, "x"), database=drive.write_dbc(tmp_path)))


def test_recording_left_by_a_crash_is_recovered_as_a_stored_log(tmp_path: Path, store: SQLStore) -> None:
    live_dir = tmp_path / "live"
    live_dir.mkdir()
    msgs = drive.drive_messages(duration_s=1.0)
    w = FlushingBLFWriter(live_dir / "live-deadbeef.blf", msgs[0].timestamp)
    for m in msgs:
        w.on_message_received(m)
    w.flush()  # the process "dies" here: no stop(), header never finalised
    (live_dir / "live-empty.blf").write_bytes(b"")
    manager = LiveManager(store, live_dir, source_for)
    found = manager.recover()
    stored = [f for f in found if f.log_id]
    assert len(stored) == 1 and store.get_log(stored[0].log_id).frames == len(msgs)
    assert any(f.note and "not stored" in f.note for f in found)
    w.file.close()
