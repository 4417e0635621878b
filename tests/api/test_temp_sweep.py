"""A server killed with ``kill -9`` mid-upload leaves its partial file; the next start sweeps it at once
(its writer is gone), not only once it is older than the upload idle limit."""

from __future__ import annotations

import signal
import socket
import time
from pathlib import Path

from tests.api.conftest import Server
from tests.api.test_writes import leftovers


def test_an_upload_cut_by_kill_9_is_swept_at_restart(tmp_path: Path) -> None:
    server = Server(tmp_path / "data").start()
    try:
        host, port = server.url.removeprefix("http://").split(":")
        with socket.create_connection((host, int(port))) as sock:
            sock.sendall(b"POST /logs?filename=drive.log HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                         b"Content-Type: application/octet-stream\r\nContent-Length: 3000000\r\n\r\n")
            sock.sendall(b"(0.000000) can0 123#00\n" * 40_000)
            deadline = time.monotonic() + 30
            while not any((server.data_dir / "tmp").iterdir()) and time.monotonic() < deadline:
                time.sleep(0.1)
            assert len(leftovers(server.data_dir)) == 1  # the partial upload, while it arrives
            server.stop(signal.SIGKILL)
        assert len(leftovers(server.data_dir)) == 1
        server.start()
        assert leftovers(server.data_dir) == []
    finally:
        server.stop()
