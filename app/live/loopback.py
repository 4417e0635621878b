"""A CAN bus across processes that never leaves the loopback interface.

Machines without CAN sockets (no ``AF_CAN``, no ``vcan``) still need a bus that two
processes can share: a replay in one process, a live session in another. python-can's
``virtual`` interface lives inside one process; ``udp_multicast`` sends to a multicast
group on the default route, which is not loopback-only; python-can's ``socketcand``
client carries no CAN FD, remote or BRS/ESI bits, never notices that its server went
away (a closed socket reads as "no data" forever) and busy-loops for 10 s on connect.

So this module provides the smallest thing that behaves like a bus:

* :class:`LoopbackHub` -- a TCP server bound to a loopback address only. Every frame a
  client sends is stamped with the hub's receive time (the "bus time", like a CAN
  controller's timestamp) and forwarded to every other client.
* :class:`LoopbackBus` -- a :class:`can.BusABC` client, so everything written against
  python-can's Bus API (our replay and live session, ``can.Notifier``, ``can.Logger``)
  runs over it unchanged. A hub that disappears raises :class:`can.CanOperationError`.

Wire format (little endian), after a 4-byte greeting ``LSB1`` in both directions::

    +-------+-----------+--------+-------+-----+------------+
    | u16   | f64       | u32    | u8    | u8  | dlc bytes  |
    | len   | timestamp | arb_id | flags | dlc | data       |
    +-------+-----------+--------+-------+-----+------------+
    len = 14 + len(data); flags are :class:`app.ingest.frames.FrameFlag` bits.

Run a hub as its own process with ``python -m app.live.loopback --port 29536``.
"""

from __future__ import annotations

import argparse
import contextlib
import ipaddress
import select
import selectors
import signal
import socket
import struct
import sys
import threading
import time
from collections import deque
from collections.abc import Sequence
from types import FrameType
from typing import Any

import can

from app.errors import InputError
from app.ingest.frames import FrameFlag
from app.live.convert import message_flags
from app.settings import DEFAULT_HUB_PORT

GREETING = b"LSB1"
RECORD = struct.Struct("<HdIBB")  # len, timestamp s, arb_id, flags, dlc
_BODY_FIXED = RECORD.size - 2
DEFAULT_PORT = DEFAULT_HUB_PORT
MAX_CLIENT_BACKLOG = 4 * 1024 * 1024  # bytes queued per slow client before frames are dropped for it


def require_loopback(host: str) -> str:
    """Resolve ``host`` and refuse anything that is not a loopback address.

    Returns the numeric address. Raises :class:`app.errors.InputError` naming the host.
    """
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except OSError as exc:
        raise InputError(f"loopback bus host {host!r} cannot be resolved: {exc}") from exc
    addr = str(infos[0][4][0])
    if not ipaddress.ip_address(addr).is_loopback:
        raise InputError(f"loopback bus host {host!r} resolves to {addr}, which is not a loopback address")
    return addr


def parse_endpoint(channel: str | None, default_port: int = DEFAULT_PORT) -> tuple[str, int]:
    """``"127.0.0.1:29536"``, ``"localhost"`` or ``":29536"`` -> ``(host, port)``."""
    text = (channel or "").strip()
    host, _, port_text = text.rpartition(":") if ":" in text else (text, "", "")
    host = host or "127.0.0.1"
    try:
        port = int(port_text) if port_text else default_port
    except ValueError as exc:
        raise InputError(f"loopback bus channel {channel!r}: port {port_text!r} is not a number") from exc
    if not 0 < port < 65536:
        raise InputError(f"loopback bus channel {channel!r}: port {port} out of range")
    return host, port


def encode_message(msg: can.Message, timestamp: float | None = None) -> bytes:
    flags = message_flags(msg) & ~FrameFlag.TX  # direction is the receiver's business on the hub
    data = bytes(msg.data or b"")
    ts = msg.timestamp if timestamp is None else timestamp
    return RECORD.pack(_BODY_FIXED + len(data), ts, msg.arbitration_id, flags, msg.dlc) + data


def decode_records(buf: bytearray) -> tuple[list[can.Message], int]:
    """Parse complete records from ``buf``; returns the messages and the bytes consumed."""
    out: list[can.Message] = []
    pos = 0
    n = len(buf)
    while n - pos >= 2:
        (length,) = struct.unpack_from("<H", buf, pos)
        if length < _BODY_FIXED:
            raise can.CanOperationError(f"loopback bus: corrupt record length {length} at stream offset {pos}")
        if n - pos < 2 + length:
            break
        _, ts, arb_id, flags, dlc = RECORD.unpack_from(buf, pos)
        data = bytes(buf[pos + RECORD.size: pos + 2 + length])
        out.append(can.Message(
            timestamp=ts, arbitration_id=arb_id, is_extended_id=bool(flags & FrameFlag.EXTENDED),
            is_fd=bool(flags & FrameFlag.FD), is_error_frame=bool(flags & FrameFlag.ERROR),
            is_remote_frame=bool(flags & FrameFlag.REMOTE), bitrate_switch=bool(flags & FrameFlag.BRS),
            error_state_indicator=bool(flags & FrameFlag.ESI), dlc=dlc, data=data, is_rx=True, check=False,
        ))
        pos += 2 + length
    return out, pos


def _split_records(buf: bytearray) -> tuple[list[bytearray], int]:
    """Split complete raw records (for the hub, which only restamps and forwards)."""
    out: list[bytearray] = []
    pos = 0
    n = len(buf)
    while n - pos >= 2:
        (length,) = struct.unpack_from("<H", buf, pos)
        if length < _BODY_FIXED:
            raise ValueError(f"corrupt record length {length}")
        if n - pos < 2 + length:
            break
        out.append(buf[pos: pos + 2 + length])
        pos += 2 + length
    return out, pos


class LoopbackBus(can.BusABC):
    """python-can Bus client of a :class:`LoopbackHub`.

    Parameters
    ----------
    channel : str
        ``"host:port"`` of the hub; the host must be a loopback address.
    receive_own_messages : bool
        Also deliver frames this client sent (as python-can's virtual bus does).
    connect_timeout : float
        Seconds to wait for the hub; a refused or silent hub raises
        :class:`can.CanInitializationError` at once instead of retrying.
    """

    def __init__(self, channel: Any = None, receive_own_messages: bool = False,
                 connect_timeout: float = 2.0, **kwargs: Any) -> None:
        try:
            host, port = parse_endpoint(None if channel is None else str(channel))
            addr = require_loopback(host)
        except InputError as exc:
            raise can.CanInitializationError(str(exc)) from exc
        self.channel_info = f"lashscope loopback hub {addr}:{port}"
        self.channel = f"{addr}:{port}"
        self._own = receive_own_messages
        self._pending: deque[can.Message] = deque()
        self._inbuf = bytearray()
        try:
            sock = socket.create_connection((addr, port), timeout=connect_timeout)
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(GREETING)
            greeting = sock.recv(len(GREETING))
        except OSError as exc:
            raise can.CanInitializationError(f"no loopback hub at {addr}:{port}: {exc}") from exc
        if greeting != GREETING:  # whatever the port answered is not repeated to whoever asked
            sock.close()
            raise can.CanInitializationError(f"{addr}:{port} is not a lashscope loopback hub")
        sock.settimeout(None)
        self._sock = sock
        self._send_lock = threading.Lock()
        super().__init__(channel=self.channel, **kwargs)

    def fileno(self) -> int:
        return self._sock.fileno()

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self._pending:
            return self._pending.popleft(), False
        try:
            ready, _, _ = _select_read(self._sock, timeout)
            if not ready:
                return None, False
            chunk = self._sock.recv(8192)  # ~270 frames: parsing more at once would delay the first ones
        except OSError as exc:
            raise can.CanOperationError(f"loopback bus receive failed: {exc}") from exc
        if not chunk:
            raise can.CanOperationError(f"{self.channel_info} closed the connection")
        self._inbuf += chunk
        msgs, used = decode_records(self._inbuf)
        del self._inbuf[:used]
        # Messages keep channel None: a hub is one bus. The endpoint string "127.0.0.1:29536" would be
        # read by python-can's log writers (can.util.channel2int) as CAN channel 29536.
        self._pending.extend(msgs)
        if self._pending:
            return self._pending.popleft(), False
        return None, False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        now = time.time()
        try:
            with self._send_lock:
                self._sock.sendall(encode_message(msg, now))
        except OSError as exc:
            raise can.CanOperationError(f"loopback bus send failed: {exc}") from exc
        if self._own:
            own = can.Message(
                timestamp=now, arbitration_id=msg.arbitration_id, is_extended_id=msg.is_extended_id,
                is_fd=msg.is_fd, is_error_frame=msg.is_error_frame, is_remote_frame=msg.is_remote_frame,
                bitrate_switch=msg.bitrate_switch, error_state_indicator=msg.error_state_indicator,
                dlc=msg.dlc, data=bytes(msg.data), is_rx=False, channel=self.channel, check=False,
            )
            self._pending.append(own)

    def shutdown(self) -> None:
        super().shutdown()
        with contextlib.suppress(OSError):
            self._sock.close()


def _select_read(sock: socket.socket, timeout: float | None) -> tuple[list[Any], list[Any], list[Any]]:
    return select.select([sock], [], [], timeout)


class _Client:
    __slots__ = ("dropped", "greeted", "inbuf", "outbuf", "sock")

    def __init__(self, sock: socket.socket) -> None:
        self.sock = sock
        self.inbuf = bytearray()
        self.outbuf = bytearray()
        self.greeted = False
        self.dropped = 0


class LoopbackHub:
    """The shared medium: forwards every frame a client sends to all other clients.

    Parameters
    ----------
    host : str
        Loopback address to bind (anything else is refused).
    port : int
        TCP port; 0 picks a free one (read :attr:`port` after :meth:`start`).
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0) -> None:
        self._addr = require_loopback(host)
        self._want_port = port
        self._sel = selectors.DefaultSelector()
        self._clients: dict[int, _Client] = {}
        self._listener: socket.socket | None = None
        self._thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._wake_r, self._wake_w = socket.socketpair()
        self.frames_forwarded = 0
        self.port = 0

    @property
    def channel(self) -> str:
        """The ``--channel`` value clients use."""
        return f"{self._addr}:{self.port}"

    @property
    def clients(self) -> int:
        return sum(1 for c in self._clients.values() if c.greeted)

    @property
    def dropped(self) -> int:
        return sum(c.dropped for c in self._clients.values())

    def start(self) -> LoopbackHub:
        lst = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        lst.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        lst.bind((self._addr, self._want_port))
        lst.listen(16)
        lst.setblocking(False)
        self._listener = lst
        self.port = int(lst.getsockname()[1])
        self._sel.register(lst, selectors.EVENT_READ, None)
        self._sel.register(self._wake_r, selectors.EVENT_READ, "wake")
        self._thread = threading.Thread(target=self._run, name=f"loopback-hub-{self.port}", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Close every client connection and the listener (clients see the bus disappear)."""
        self._stop.set()
        self._wake_w.send(b"x")
        if self._thread is not None:
            self._thread.join(5.0)
        for c in list(self._clients.values()):
            c.sock.close()
        self._clients.clear()
        if self._listener is not None:
            self._listener.close()
        self._sel.close()
        self._wake_r.close()
        self._wake_w.close()

    def __enter__(self) -> LoopbackHub:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.is_set():
            for key, events in self._sel.select(timeout=0.5):
                if key.data == "wake":
                    return
                if key.data is None:
                    self._accept()
                    continue
                client: _Client = key.data
                if events & selectors.EVENT_READ:
                    self._read(client)
                if events & selectors.EVENT_WRITE and client.sock.fileno() in self._clients:
                    self._write(client)

    def _accept(self) -> None:
        assert self._listener is not None
        try:
            sock, _ = self._listener.accept()
        except OSError:
            return
        sock.setblocking(False)
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        client = _Client(sock)
        self._clients[sock.fileno()] = client
        self._sel.register(sock, selectors.EVENT_READ, client)

    def _drop(self, client: _Client) -> None:
        self._clients.pop(client.sock.fileno(), None)
        with contextlib.suppress(KeyError, ValueError):
            self._sel.unregister(client.sock)
        client.sock.close()

    def _read(self, client: _Client) -> None:
        try:
            chunk = client.sock.recv(262144)
        except (BlockingIOError, InterruptedError):
            return
        except OSError:
            chunk = b""
        if not chunk:
            self._drop(client)
            return
        client.inbuf += chunk
        if not client.greeted:
            if len(client.inbuf) < len(GREETING):
                return
            if bytes(client.inbuf[: len(GREETING)]) != GREETING:
                self._drop(client)
                return
            del client.inbuf[: len(GREETING)]
            client.greeted = True
            client.outbuf += GREETING
            self._write(client)
        try:
            records, used = _split_records(client.inbuf)
        except ValueError:
            self._drop(client)
            return
        del client.inbuf[:used]
        if not records:
            return
        stamp = struct.pack("<d", time.time())
        payload = bytearray()
        for rec in records:
            rec[2:10] = stamp
            payload += rec
        self.frames_forwarded += len(records)
        for other in list(self._clients.values()):
            if other is client or not other.greeted:
                continue
            if len(other.outbuf) + len(payload) > MAX_CLIENT_BACKLOG:
                other.dropped += len(records)
                continue
            other.outbuf += payload
            self._write(other)

    def _write(self, client: _Client) -> None:
        if client.outbuf:
            try:
                sent = client.sock.send(client.outbuf)
                del client.outbuf[:sent]
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:
                self._drop(client)
                return
        want = selectors.EVENT_READ | (selectors.EVENT_WRITE if client.outbuf else 0)
        with contextlib.suppress(KeyError, ValueError):
            self._sel.modify(client.sock, want, client)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m app.live.loopback",
                                     description="Serve a loopback-only CAN bus shared by processes.")
    parser.add_argument("--host", default="127.0.0.1", help="loopback address to bind (default 127.0.0.1)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help=f"TCP port (default {DEFAULT_PORT})")
    args = parser.parse_args(argv)
    try:
        hub = LoopbackHub(args.host, args.port).start()
    except (InputError, OSError) as exc:
        print(f"loopback hub: {exc}", file=sys.stderr)
        return 2
    print(f"loopback CAN hub on {hub.channel} (use --interface tcp_loopback --channel {hub.channel})", flush=True)
    done = threading.Event()

    def _on_signal(signum: int, frame: FrameType | None) -> None:
        done.set()

    signal.signal(signal.SIGINT, _on_signal)
    signal.signal(signal.SIGTERM, _on_signal)
    done.wait()
    hub.stop()
    print(f"loopback hub stopped after forwarding {hub.frames_forwarded} frames", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
