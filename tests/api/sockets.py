"""The real server in this process, and raw sockets to talk to it.

:func:`serving` runs uvicorn with the options of ``lashscope serve`` (the connection limits,
forwarded headers, keep-alive: :func:`app.cli.serve.uvicorn_options`) and the app on a free
loopback port, in a thread: the connection tests open real sockets without paying for a server
subprocess. :func:`exchange` speaks raw bytes (what no HTTP client would send) from a chosen
loopback source address (Linux routes all of 127.0.0.0/8 to this machine), so one test can be
several clients.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import uvicorn

from app.api.main import create_app
from app.cli.serve import uvicorn_options
from app.settings import Settings
from tests.api.conftest import free_port


@dataclass
class Served:
    port: int
    settings: Settings

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"


@contextmanager
def serving(data_dir: Path, **settings: Any) -> Iterator[Served]:
    """``lashscope serve``'s server with ``settings`` on a free port of 127.0.0.1, until the block ends."""
    cfg = Settings(data_dir=data_dir, port=free_port(), **settings)
    config = uvicorn.Config(create_app(cfg), host=cfg.host, port=cfg.port, log_config=None, log_level="warning",
                            **uvicorn_options(cfg))
    server = uvicorn.Server(config)
    thread = threading.Thread(target=lambda: asyncio.run(server.serve()), daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started:
        if not thread.is_alive() or time.monotonic() > deadline:
            raise RuntimeError("the server did not start")
        time.sleep(0.05)
    try:
        yield Served(cfg.port, cfg)
    finally:
        server.should_exit = True
        thread.join(30)


def connect(port: int, src: str = "127.0.0.1", timeout: float = 30.0) -> socket.socket:
    """A TCP connection to 127.0.0.1:``port`` from the loopback address ``src``."""
    s = socket.socket()
    s.settimeout(timeout)
    s.bind((src, 0))
    s.connect(("127.0.0.1", port))
    return s


def read_all(s: socket.socket) -> bytes:
    """Everything the server sends until it closes (a reset after its answer counts as the end)."""
    out = b""
    while True:
        try:
            chunk = s.recv(65536)
        except ConnectionResetError:
            return out
        if not chunk:
            return out
        out += chunk


def exchange(port: int, data: bytes, src: str = "127.0.0.1", timeout: float = 30.0) -> bytes:
    """Send ``data`` on a new connection and return all the server answers before it closes."""
    with connect(port, src, timeout) as s:
        with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # refused at once: the answer is readable
            s.sendall(data)
        return read_all(s)


def status_of(reply: bytes) -> int:
    """The status code of a raw HTTP/1.1 reply (0 if there is none)."""
    parts = reply.split(b" ", 2)
    return int(parts[1]) if reply.startswith(b"HTTP/1.1 ") and len(parts) > 1 and parts[1].isdigit() else 0


def get(path: str = "/health", headers: str = "") -> bytes:
    """A raw ``GET`` that closes the connection after the answer."""
    return f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n{headers}\r\n".encode()
