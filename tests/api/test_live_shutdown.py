"""A server stopped (SIGTERM) while a live session records: the recording is stored and analysed after a restart.

The bus is the project's loopback hub (python-can's ``virtual`` bus does not cross processes): this
process replays a short scripted drive onto it while the server's session records and decodes it.
A client keeps the session's event stream open, which must not hold up the stop.
"""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path

import httpx
import pytest

from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink
from app.live.loopback import LoopbackHub
from app.live.replay import Replayer
from app.settings import default_dbc_dir
from tests.api.conftest import Server, create_vehicle, free_port, wait_for


def _hold_stream(url: str, lines: list[str]) -> None:
    try:
        with httpx.stream("GET", url, timeout=httpx.Timeout(60.0)) as r:
            for line in r.iter_lines():
                lines.append(line)
    except httpx.HTTPError:
        lines.append("<cut>")


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("live-drive") / "drive.blf"
    dbc = default_dbc_dir()
    build_demo_log(path, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml", Scenario(duration_s=9.0))
    return path


def test_sigterm_stores_the_live_recording_and_its_analysis_runs_after_restart(
        tmp_path: Path, drive_log: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    frames = sum(len(c) for c in open_log(drive_log).chunks())
    port = free_port()
    monkeypatch.setenv("LASHSCOPE_LIVE_CHANNELS", f"tcp_loopback:127.0.0.1:{port}")  # the hub's port, allowed
    srv = Server(data).start()
    try:
        with LoopbackHub(port=port) as hub, httpx.Client(base_url=srv.url, timeout=30.0) as c:
            create_vehicle(c)
            r = c.post("/live/sessions", json={"interface": "tcp_loopback", "channel": hub.channel, "vehicle": "ev"})
            assert r.status_code == 201, r.text
            sid = r.json()["id"]
            stream: list[str] = []
            reader = threading.Thread(target=_hold_stream, args=(f"{srv.url}/live/sessions/{sid}/stream", stream),
                                      daemon=True)
            reader.start()
            link = BusLink(BusConfig("tcp_loopback", hub.channel))
            link.open()
            try:
                Replayer(link, lambda: open_log(drive_log).chunks(), rate=1.5).run()
            finally:
                link.close()
            deadline = time.monotonic() + 20
            while c.get(f"/live/sessions/{sid}").json()["frames_processed"] < frames:
                assert time.monotonic() < deadline, "the session did not take every frame"
                time.sleep(0.1)
            assert c.get("/logs").json() == []  # nothing stored while the session runs
            assert stream, "the event stream was not open"

            assert srv.proc is not None
            t0 = time.monotonic()
            srv.proc.send_signal(signal.SIGTERM)
            code = srv.proc.wait(30)
            stopped_in = time.monotonic() - t0
    finally:
        srv.stop()
    assert code in (0, -signal.SIGTERM)  # uvicorn re-raises the signal once its shutdown is complete
    # the open stream was cut after the grace period (5 s), not waited for
    assert stopped_in < 15.0, stopped_in
    assert not list((data / "live").glob("*.blf")), "the recording was left behind instead of stored"

    srv = Server(data).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=30.0) as c:
            (stored,) = c.get("/logs").json()
            assert stored["format"] == "blf" and stored["frames"] == frames
            assert stored["filename"] == f"live-{sid}.blf"
            (analysis,) = c.get("/analyses").json()
            assert analysis["log_id"] == stored["id"]
            done = wait_for(c, analysis["id"])
            assert done["status"] == "done", done
            events = c.get(f"/analyses/{analysis['id']}/events").json()
            assert events["count"] >= 2
    finally:
        srv.stop()
