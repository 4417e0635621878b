"""REST live sessions through real HTTP: a server process decodes a bus another process replays onto."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink
from app.live.loopback import LoopbackHub
from app.live.replay import Replayer
from tests.api.conftest import free_port
from tests.live import drive

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    tmp_path = tmp_path_factory.mktemp("live-api")
    dbc_dir = tmp_path / "dbc"
    dbc_dir.mkdir()
    drive.write_dbc(dbc_dir)
    port = free_port()
    url = f"http://127.0.0.1:{port}"
    env = {**os.environ, "LASHSCOPE_DBC_DIR": str(dbc_dir), "PYTHONPATH": str(REPO)}
    env.pop("LASHSCOPE_LIVE_INTERFACES", None)
    # these tests start loopback hubs on free ports: the operator allows any (the default allows one port only)
    env["LASHSCOPE_LIVE_CHANNELS"] = "virtual:*,tcp_loopback:*,socketcan:*"
    proc = subprocess.Popen([sys.executable, "-m", "app", "serve", "--host", "127.0.0.1", "--port", str(port),
                             "--data-dir", str(tmp_path / "data"), "--log-level", "warning"],
                            cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 60
        while True:
            assert proc.poll() is None, proc.stderr.read().decode() if proc.stderr else ""
            try:
                if httpx.get(f"{url}/health", timeout=1.0).status_code == 200:
                    break
            except httpx.HTTPError:
                pass
            assert time.monotonic() < deadline, "server did not start"
            time.sleep(0.2)
        yield url
    finally:
        proc.terminate()
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
        if proc.stderr is not None:
            proc.stderr.close()


def _read_stream(url: str, out: list[tuple[str, dict[str, Any]]]) -> None:
    with httpx.stream("GET", url, timeout=httpx.Timeout(30.0)) as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        kind = None
        for line in r.iter_lines():
            if line.startswith("event: "):
                kind = line[7:]
            elif line.startswith("data: ") and kind is not None:
                out.append((kind, json.loads(line[6:])))
                if kind == "end":
                    return


def test_live_session_over_http(server: str, tmp_path: Path) -> None:
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=2.0, period_s=0.8, error_frames=2))
    n = sum(len(c) for c in open_log(log).chunks())
    with LoopbackHub() as hub:
        r = httpx.post(f"{server}/live/sessions", json={"interface": "tcp_loopback", "channel": hub.channel,
                                                        "database": "drive.dbc"})
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        assert r.json()["state"] == "running" and r.json()["bus"]["state"] == "connected"
        got: list[tuple[str, dict[str, Any]]] = []
        reader = threading.Thread(target=_read_stream, args=(f"{server}/live/sessions/{sid}/stream", got))
        reader.start()
        time.sleep(0.5)
        link = BusLink(BusConfig("tcp_loopback", hub.channel))
        link.open()
        try:
            Replayer(link, lambda: open_log(log).chunks()).run()
        finally:
            link.close()
        deadline = time.monotonic() + 10
        while httpx.get(f"{server}/live/sessions/{sid}").json()["frames_processed"] < n:
            assert time.monotonic() < deadline
            time.sleep(0.1)
        st = httpx.get(f"{server}/live/sessions/{sid}").json()
        assert st["frames_received"] == n and st["bus_errors"] == 2 and st["frames_dropped"] == 0
        assert st["unknown_ids"] == {f"0x{drive.UNKNOWN_ID:X}": 20} and st["decode_errors"] == 0
        assert st["frames_per_s"] >= 0 and st["latency_ms"]["p50"] is not None
        stop = httpx.post(f"{server}/live/sessions/{sid}/stop", timeout=30)
        assert stop.status_code == 200, stop.text
        reader.join(10)
    body = stop.json()
    assert body["session"]["state"] == "stopped" and body["analysis_id"] is None
    stored = httpx.get(f"{server}/logs/{body['log_id']}").json()
    assert stored["frames"] == n and stored["format"] == "blf"
    kinds = [k for k, _ in got]
    assert kinds[-1] == "end" and "status" in kinds
    samples = [d["channels"] for k, d in got if k == "samples"]
    torque = [v for s in samples for v in s.get("Inverter.MotorTorque", {}).get("v", [])]
    assert len(torque) == 200 and min(torque) == pytest.approx(-60.0) and max(torque) == pytest.approx(140.0)
    # stopping twice answers the same result
    again = httpx.post(f"{server}/live/sessions/{sid}/stop", timeout=30).json()
    assert again["log_id"] == body["log_id"]


@pytest.mark.parametrize(("body", "status", "code"), [
    ({"interface": "udp_multicast", "channel": "239.0.0.1", "database": "drive.dbc"}, 400, "invalid_input"),
    ({"interface": "no_such_bus", "database": "drive.dbc"}, 400, "invalid_input"),
    ({"interface": "tcp_loopback", "channel": "127.0.0.1:1", "database": "drive.dbc"}, 503, "live_bus_error"),
    ({"interface": "virtual", "channel": "x", "database": "../../etc/passwd"}, 400, "invalid_input"),
    ({"interface": "virtual", "channel": "x"}, 400, "invalid_input"),
    ({"interface": "virtual", "channel": "x", "vehicle": "nope"}, 404, "not_found"),
])
def test_bad_start_requests(server: str, body: dict[str, Any], status: int, code: str) -> None:
    r = httpx.post(f"{server}/live/sessions", json=body)
    assert (r.status_code, r.json()["code"]) == (status, code), r.text


def test_unknown_session_is_404(server: str) -> None:
    r = httpx.get(f"{server}/live/sessions/nope")
    assert (r.status_code, r.json()["code"]) == (404, "not_found")
