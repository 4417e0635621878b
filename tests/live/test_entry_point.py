"""``tcp_loopback`` as a python-can interface (entry point ``can.interface``): can.Bus and its tools join our hub."""

from __future__ import annotations

import signal
import subprocess
import sys
import time
from importlib.metadata import entry_points
from pathlib import Path

import can
import pytest

from app.ingest.readers import open_log
from app.live.convert import messages_to_chunk
from app.live.loopback import LoopbackBus, LoopbackHub
from tests.conftest import REPO
from tests.live import drive
from tests.live.test_interop import _ours


@pytest.fixture()
def hub():  # type: ignore[no-untyped-def]
    h = LoopbackHub().start()
    yield h
    h.stop()


def _wait(cond, timeout: float = 20.0) -> bool:  # type: ignore[no-untyped-def]
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.02)
    return False


def test_entry_point_is_registered() -> None:
    (ep,) = [e for e in entry_points(group="can.interface") if e.name == "tcp_loopback"]
    assert ep.value == "app.live.loopback:LoopbackBus" and ep.load() is LoopbackBus
    assert "tcp_loopback" in can.VALID_INTERFACES


def test_can_bus_by_interface_name(hub: LoopbackHub) -> None:
    with can.Bus(interface="tcp_loopback", channel=hub.channel) as a, \
            can.Bus(interface="tcp_loopback", channel=hub.channel) as b:
        assert isinstance(a, LoopbackBus)
        assert _wait(lambda: hub.clients == 2)
        a.send(can.Message(arbitration_id=0x18DAF110, is_extended_id=True, data=b"\x01\x02\x03"))
        got = b.recv(5.0)
    assert got is not None and (got.arbitration_id, got.is_extended_id, bytes(got.data)) == \
        (0x18DAF110, True, b"\x01\x02\x03")
    with pytest.raises(can.CanInitializationError, match="loopback"):
        can.Bus(interface="tcp_loopback", channel="192.0.2.1:29536")  # never leaves loopback


def _ctrl_c_as_in_a_shell() -> None:
    """In the child before exec: Ctrl-C delivered and handled by default, as an interactive shell starts a program.
    An ignored SIGINT survives exec, and the suite's own process can start with one: a non-interactive shell starts
    a background job with SIGINT and SIGQUIT ignored (``SigIgn: 0000000000000006`` in its /proc status), and a
    runner that starts the tests so passes that on (the logger then never sees its Ctrl-C)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def test_python_can_logger_process_records_our_hub(hub: LoopbackHub, tmp_path: Path) -> None:
    out = tmp_path / "logged.asc"
    logger = subprocess.Popen([sys.executable, "-m", "can.logger", "-i", "tcp_loopback", "-c", hub.channel,
                               "-f", str(out)], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                              preexec_fn=_ctrl_c_as_in_a_shell)
    try:
        assert _wait(lambda: hub.clients == 1 or logger.poll() is not None), "can.logger did not connect"
        assert logger.poll() is None, logger.communicate()[1]
        msgs = drive.drive_messages(duration_s=0.5, error_frames=1)
        with can.Bus(interface="tcp_loopback", channel=hub.channel) as tx:
            assert _wait(lambda: hub.clients == 2)
            for m in msgs:
                tx.send(m)
        time.sleep(1.0)  # let the logger write what it received
    finally:
        logger.send_signal(signal.SIGINT)  # can.logger stops and closes its file on Ctrl-C
        try:  # a loaded machine can take a while to run its handler and write the file
            _, err = logger.communicate(timeout=90)
        except subprocess.TimeoutExpired:
            logger.kill()
            _, err = logger.communicate()
            err = f"can.logger did not stop within 90 s of Ctrl-C; {err}"
    assert logger.returncode == 0, err
    with open_log(out) as reader:
        chunks = list(reader.chunks())
        assert reader.report.ok, reader.report.issues
    assert _ours(chunks) == _ours([messages_to_chunk(msgs, 0.0)])
    assert all((c.channel == 0).all() for c in chunks)  # ASC channel 1: the hub's address is not a channel number
