"""Replay in one process (the CLI), live session in another, over the loopback-only TCP bus."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

from app.ingest.readers import open_log
from app.live.analyzer import LiveAnalyzer
from app.live.bus import BusConfig
from app.live.decoding import source_for
from app.live.loopback import LoopbackHub
from app.live.session import LiveSession
from tests.live import drive
from tests.live.procs import REPO, lashscope, signal_when_ready
from tests.live.test_live_events import _same, offline_events


def test_cli_replay_into_live_session_in_another_process(tmp_path: Path) -> None:
    dbc = drive.write_dbc(tmp_path)
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=5.0, period_s=1.6, error_frames=2))
    original = list(open_log(log).chunks())
    with LoopbackHub() as hub:
        source = source_for(dbc, drive.map_of(dbc))[0]
        session = LiveSession(BusConfig("tcp_loopback", hub.channel), source, record_path=tmp_path / "rec.blf",
                              analyzer=LiveAnalyzer()).start()
        try:
            proc = subprocess.run(lashscope("replay", str(log), "--interface", "tcp_loopback", "--channel",
                                             hub.channel, "--json"),
                                  cwd=REPO, capture_output=True, text=True, timeout=60)
            assert proc.returncode == 0, proc.stderr
            summary = json.loads(proc.stdout)
            assert session.wait_idle()
        finally:
            session.stop()
    recorded = list(open_log(tmp_path / "rec.blf").chunks())
    n = sum(len(c) for c in original)
    assert summary["frames_sent"] == n and summary["send_failures"] == 0
    st = session.status()
    assert st["frames_received"] == n and st["frames_dropped"] == 0 and st["bus_errors"] == 2
    assert drive.frames_of(recorded) == drive.frames_of(original)
    # paced at rate 1.0: no frame leaves before its deadline, so the replay lasts the log's span at least, and
    # the bus time the hub stamped spans the log too (not a burst); the pacing error's bounds live in bench/live.py
    span_s = drive.span_s(original)
    assert summary["wall_s"] >= span_s - 1e-6 and abs(summary["log_time_s"] - span_s) < 1e-6, summary
    assert drive.span_s(recorded) > 0.5 * span_s
    expected = offline_events(tmp_path / "rec.blf", dbc)
    live = [{k: v for k, v in e.items() if k != "provisional"} for e in session.events]
    assert len(expected) == len(live) == 2
    for a, b in zip(live, expected, strict=True):
        assert all(_same(a[k], b[k], key=k) for k in a), (a, b)


def test_replay_ctrl_c_stops_cleanly_with_a_summary(tmp_path: Path) -> None:
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=3.0))
    with LoopbackHub() as hub:
        code, out, err = signal_when_ready(["replay", str(log), "-i", "tcp_loopback", "-c", hub.channel, "--loop"],
                                           lambda: hub.frames_forwarded >= 300, signal.SIGINT)
    assert code == 130, err
    assert "replay stopped by Ctrl-C" in out and "pacing error p50" in out
    assert "Traceback" not in err


def test_replay_of_a_missing_or_corrupt_log_is_a_one_line_error(tmp_path: Path) -> None:
    bad = tmp_path / "bad.blf"
    bad.write_bytes(b"LOGG" + os.urandom(200))
    for path in (tmp_path / "missing.blf", bad):
        proc = subprocess.run(lashscope("replay", str(path), "-i", "virtual", "-c", "x"), cwd=REPO,
                              capture_output=True, text=True, timeout=60)
        assert proc.returncode == 2, proc.stderr
        assert proc.stderr.startswith("lashscope: error [") and "Traceback" not in proc.stderr


def test_live_command_records_and_reports_events(tmp_path: Path) -> None:
    dbc = drive.write_dbc(tmp_path)
    log = drive.write_blf(tmp_path / "drive.blf", drive.drive_messages(duration_s=4.0, period_s=1.6))
    out = tmp_path / "cli.blf"
    with LoopbackHub() as hub:
        def replay_the_drive() -> None:
            link_proc = subprocess.run(lashscope("replay", str(log), "-i", "tcp_loopback", "-c", hub.channel,
                                                 "--rate", "2"), cwd=REPO, capture_output=True, text=True, timeout=60)
            assert link_proc.returncode == 0, link_proc.stderr
            time.sleep(0.5)

        code, stdout, err = signal_when_ready(
            ["live", "-i", "tcp_loopback", "-c", hub.channel, "--dbc", str(dbc), "--map", str(drive.map_of(dbc)),
             "--out", str(out), "--json", "--status-every", "0"],
            lambda: hub.clients >= 1, signal.SIGINT, ready_within_s=30, exit_within_s=30,
            before_signal=replay_the_drive)
    assert code == 0, err
    lines = [json.loads(line) for line in stdout.splitlines()]
    events = [x["event"] for x in lines if "event" in x]
    summary = lines[-1]
    n = sum(len(c) for c in open_log(log).chunks())
    assert summary["status"]["frames_processed"] == n and summary["status"]["state"] == "stopped"
    assert [e["kind"] for e in events] == ["tip_in", "tip_out"]
    assert sum(len(c) for c in open_log(out).chunks()) == n
