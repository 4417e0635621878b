"""``replay`` / ``live`` command lifecycle: argument checks before the bus, a bus absent at start,
SIGTERM, and the store directory."""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import threading
import time
from pathlib import Path

import pytest

from app.cli import main
from app.errors import LiveBusError
from app.live.bus import Backoff, BusConfig, BusLink
from app.live.loopback import LoopbackHub
from tests.live import drive
from tests.live.procs import REPO, lashscope, signal_when_ready


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("drive")
    return drive.write_blf(folder / "drive.blf", drive.drive_messages(duration_s=1.0))


@pytest.mark.parametrize(("extra", "message"), [
    (["--rate", "1e-300"], "--rate must be between 0.001 and 1000"),
    (["--rate", "1e9"], "--rate must be between 0.001 and 1000"),
    (["--rate", "nan"], "--rate must be between"),
    (["--rate", "0"], "--rate must be between"),
    (["--connect-timeout", "-1"], "--connect-timeout must be between"),
    (["--ids", "0xZZ"], "--ids"),
])
def test_replay_refuses_bad_arguments_before_opening_the_bus(log: Path, extra: list[str], message: str) -> None:
    with LoopbackHub() as hub:
        proc = subprocess.run(lashscope("replay", str(log), "-i", "tcp_loopback", "-c", hub.channel, *extra),
                              cwd=REPO, capture_output=True, text=True, timeout=60)
        clients_seen = hub.clients
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.startswith("lashscope: error [invalid_input]") and message in proc.stderr, proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr  # no traceback, no "bus was not properly shut down"
    assert clients_seen == 0


def test_replay_waits_for_a_bus_that_appears_after_start(log: Path) -> None:
    port = _free_port()
    proc = subprocess.Popen(lashscope("replay", str(log), "-i", "tcp_loopback", "-c", f"127.0.0.1:{port}",
                                       "--connect-timeout", "20", "--json"),
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        time.sleep(1.0)  # the replay is up (and retrying) before the bus exists
        assert proc.poll() is None
        with LoopbackHub(port=port):
            out, err = proc.communicate(timeout=40)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    summary = json.loads(out)
    assert summary["frames_sent"] > 0 and summary["send_failures"] == 0


def test_replay_gives_up_on_an_absent_bus_after_the_connect_timeout(log: Path) -> None:
    port = _free_port()
    t = time.monotonic()
    proc = subprocess.run(lashscope("replay", str(log), "-i", "tcp_loopback", "-c", f"127.0.0.1:{port}",
                                     "--connect-timeout", "1"), cwd=REPO, capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2
    assert proc.stderr.startswith("lashscope: error [live_bus_error]") and "attempts" in proc.stderr, proc.stderr
    assert proc.stderr.count("\n") == 1
    assert time.monotonic() - t >= 1.0


def test_link_open_retries_with_backoff_until_the_bus_appears() -> None:
    port = _free_port()
    hub = LoopbackHub(port=port)
    timer = threading.Timer(0.6, hub.start)
    timer.start()
    link = BusLink(BusConfig("tcp_loopback", f"127.0.0.1:{port}"), backoff=Backoff(0.05, 2.0, 0.2))
    try:
        link.open(connect_timeout_s=10.0)
        assert link.status.state == "connected" and link.status.connects == 1
        assert link.status.reconnect_attempts >= 2  # it failed (and retried) before the hub came up
    finally:
        timer.join()
        link.close()
        hub.stop()


def test_link_open_without_timeout_fails_at_once() -> None:
    port = _free_port()
    link = BusLink(BusConfig("tcp_loopback", f"127.0.0.1:{port}"))
    t = time.monotonic()
    with pytest.raises(LiveBusError, match="cannot open CAN bus"):
        link.open()
    assert time.monotonic() - t < 2.0 and link.status.reconnect_attempts == 0


def test_replay_sigterm_stops_cleanly_with_a_summary(log: Path) -> None:
    with LoopbackHub() as hub:
        code, out, err = signal_when_ready(["replay", str(log), "-i", "tcp_loopback", "-c", hub.channel, "--loop"],
                                           lambda: hub.frames_forwarded >= 100, signal.SIGTERM)
    assert code == 143, err
    assert "replay stopped by SIGTERM" in out and "pacing error p50" in out
    assert "Traceback" not in err


def test_live_sigterm_stops_cleanly_with_a_summary(tmp_path: Path) -> None:
    dbc = drive.write_dbc(tmp_path)
    out = tmp_path / "rec.blf"
    with LoopbackHub() as hub:
        code, stdout, err = signal_when_ready(
            ["live", "-i", "tcp_loopback", "-c", hub.channel, "--dbc", str(dbc), "--out", str(out), "--json",
             "--status-every", "0"],
            lambda: hub.clients >= 1, signal.SIGTERM, ready_within_s=30, exit_within_s=30)
    assert code == 0, err
    summary = json.loads(stdout.splitlines()[-1])
    assert summary["status"]["state"] == "stopped" and out.is_file()


@pytest.mark.parametrize(("extra", "message"), [
    (["--duration", "-1"], "--duration"),
    (["--status-every", "-1"], "--status-every"),
    (["--connect-timeout", "1e9"], "--connect-timeout"),
    (["--data-dir", "{tmp}"], "--data-dir is the store for --vehicle"),
])
def test_live_refuses_bad_arguments_before_opening_the_bus(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                           extra: list[str], message: str) -> None:
    dbc = drive.write_dbc(tmp_path)
    with LoopbackHub() as hub:
        code = main(["live", "-i", "tcp_loopback", "-c", hub.channel, "--dbc", str(dbc),
                     *[a.format(tmp=tmp_path) for a in extra]])
        assert hub.clients == 0
    err = capsys.readouterr().err
    assert code == 2 and "[invalid_input]" in err and message in err, err


def test_live_data_dir_is_the_store(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                    monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("LASHSCOPE_DATA_DIR", raising=False)
    data = tmp_path / "store"
    code = main(["live", "-i", "tcp_loopback", "-c", f"127.0.0.1:{_free_port()}", "--vehicle", "no-such-car",
                 "--data-dir", str(data), "--connect-timeout", "0"])
    err = capsys.readouterr().err
    assert code == 2 and "no-such-car" in err, err  # looked up in the given store ...
    assert data.is_dir() and any(data.iterdir())
    assert not (tmp_path / "lashscope-data").exists()  # ... not in the default one
