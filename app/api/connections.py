"""Connection-level limits of ``lashscope serve``: what a client may cost before any route runs.

uvicorn's httptools protocol reads request heads without bound (a header line of any length, any
number of them), never times out a half-sent request and accepts connections until the process
runs out of file handles. :class:`LimitedHttpProtocol` is that protocol with the limits a public
server needs, enforced in its parser callbacks and timers, so everything stays on the same
compiled parser and event loop:

- **Request head.** The URL is capped (``LASHSCOPE_MAX_URL_KB``, 414 ``url_too_long``), the whole
  head -- request line and headers -- too (``LASHSCOPE_MAX_HEADER_KB``, 431 ``headers_too_large``),
  counted both from the parsed lines and from the raw bytes of a head still incomplete (the parser
  keeps a partial line in memory), and so is the number of header lines (``LASHSCOPE_MAX_HEADERS``,
  431 ``too_many_headers``).
- **Deadlines.** The head must arrive within ``LASHSCOPE_HEADER_TIMEOUT_S`` of the connection (or
  of the request's first byte on a kept-alive connection): 408 ``header_timeout`` (a connection that
  sent nothing is closed silently). The body must arrive within ``LASHSCOPE_BODY_TIMEOUT_S`` of the
  head, however it trickles: 408 ``body_timeout`` and the route sees the client disconnect (an upload
  removes its partial file). The idle limit between body chunks stays the routes'
  (``LASHSCOPE_UPLOAD_IDLE_S``); a kept-alive connection is closed after ``LASHSCOPE_KEEP_ALIVE_S``
  without a request (uvicorn's own timer).
- **Connections.** Each client address holds at most ``LASHSCOPE_MAX_CLIENT_CONNECTIONS``
  connections (an IPv6 client: its /64), refused with 429 ``too_many_connections``; the trusted
  proxies (``LASHSCOPE_TRUSTED_PROXIES``) are exempt, they carry everyone's requests. The server
  holds at most ``LASHSCOPE_MAX_CONNECTIONS``: past it the connection that has waited longest without
  a request in progress (a slow head, an idle keep-alive) is closed for the new one, so connections
  that never send a request cannot lock out those that do; only when every connection is serving a
  request is the new one refused (503 ``server_busy``).

Every refusal is the API's JSON error ``{"detail", "code"}`` with ``Connection: close``; a
malformed request is 400 ``invalid_http`` in the same shape instead of uvicorn's plain text.
"""

from __future__ import annotations

import asyncio
import contextlib
import http
import ipaddress
import json
import logging
import resource
from dataclasses import dataclass
from typing import Any

from uvicorn.protocols.http.httptools_impl import HttpToolsProtocol

from app.settings import IPNetwork, Settings, parse_networks

log = logging.getLogger("lashscope.api")
HANDLE_RESERVE = 256  # file handles kept for the store, logs, job pipes and uploads beside the connections
_IPAddress = ipaddress.IPv4Address | ipaddress.IPv6Address


def _address(host: str) -> _IPAddress | None:
    try:
        return ipaddress.ip_address(host)
    except ValueError:
        return None


@dataclass(frozen=True)
class ConnectionLimits:
    """The limits of :mod:`app.api.connections`, in bytes and seconds."""

    max_url: int
    max_head: int
    max_headers: int
    header_timeout_s: float
    body_timeout_s: float
    max_connections: int
    max_client_connections: int
    trusted: tuple[IPNetwork, ...] = ()

    @classmethod
    def from_settings(cls, s: Settings) -> ConnectionLimits:
        return cls(max_url=int(s.max_url_kb * 1024), max_head=int(s.max_header_kb * 1024), max_headers=s.max_headers,
                   header_timeout_s=s.header_timeout_s, body_timeout_s=s.body_timeout_s,
                   max_connections=s.max_connections, max_client_connections=s.max_client_connections,
                   trusted=parse_networks(s.trusted_proxies))

    def is_trusted(self, host: str) -> bool:
        addr = _address(host)
        return addr is not None and any(addr in net for net in self.trusted)


def client_key(host: str) -> str:
    """What the per-client connection cap counts: the address, for IPv6 its /64 (one subscriber's prefix)."""
    addr = _address(host)
    if isinstance(addr, ipaddress.IPv6Address) and addr.ipv4_mapped is None:
        return str(ipaddress.IPv6Network((addr, 64), strict=False))
    return host


def fit_to_file_limit(max_connections: int) -> int:
    """``max_connections``, lowered if the process may not open that many handles (after raising its soft
    limit towards the hard one): a server out of handles cannot even accept ``/health``."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = max_connections + HANDLE_RESERVE
    if soft != resource.RLIM_INFINITY and soft < need:
        target = need if hard == resource.RLIM_INFINITY else min(need, hard)
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (target, hard))
            soft = target
    if soft == resource.RLIM_INFINITY:
        return max_connections
    return max(1, min(max_connections, soft - HANDLE_RESERVE))


class ConnectionTable:
    """The server's open connections: how many per client, and which wait without a request, oldest first."""

    def __init__(self, limits: ConnectionLimits) -> None:
        self.limits = limits
        self.per_client: dict[str, int] = {}
        self.waiting: dict[LimitedHttpProtocol, None] = {}  # insertion-ordered: the first waited longest
        self.total = 0
        self.refusing = False  # a limit has just stopped the parser (see QuietRefusals)

    def admit(self, conn: LimitedHttpProtocol, host: str) -> Refusal | None:
        """Count ``conn`` in, or say why it is refused; may close the longest-waiting connection to make room."""
        key = None if self.limits.is_trusted(host) else client_key(host)
        if key is not None and self.per_client.get(key, 0) >= self.limits.max_client_connections:
            return Refusal(429, "too_many_connections", f"client {host} holds {self.limits.max_client_connections} "
                           "connections already (LASHSCOPE_MAX_CLIENT_CONNECTIONS)", {"Retry-After": "1"})
        if self.total >= self.limits.max_connections:
            if not self.waiting:
                return Refusal(503, "server_busy", f"the server is serving {self.limits.max_connections} "
                               "connections (LASHSCOPE_MAX_CONNECTIONS)", {"Retry-After": "1"})
            next(iter(self.waiting)).evict()
        if key is not None:
            self.per_client[key] = self.per_client.get(key, 0) + 1
        conn.client_key = key
        self.total += 1
        return None

    def release(self, conn: LimitedHttpProtocol) -> None:
        self.waiting.pop(conn, None)
        self.total -= 1
        key = conn.client_key
        if key is not None:
            left = self.per_client[key] - 1
            if left:
                self.per_client[key] = left
            else:
                del self.per_client[key]

    def set_waiting(self, conn: LimitedHttpProtocol, waiting: bool) -> None:
        self.waiting.pop(conn, None)
        if waiting:
            self.waiting[conn] = None


class QuietRefusals(logging.Filter):
    """uvicorn logs every stop of its parser as "Invalid HTTP request received."; a limit of ours stopping it
    is not that, and a flood of refused heads would flood the log. Passes everything else."""

    def __init__(self, table: ConnectionTable) -> None:
        super().__init__()
        self.table = table

    def filter(self, record: logging.LogRecord) -> bool:
        return not self.table.refusing


class Refusal(Exception):
    """Why a connection or request is cut off: the status, code and detail of the JSON answer."""

    def __init__(self, status: int, code: str, detail: str, headers: dict[str, str] | None = None) -> None:
        super().__init__(detail)
        self.status, self.code, self.detail, self.headers = status, code, detail, headers or {}

    def response(self) -> bytes:
        body = json.dumps({"detail": self.detail, "code": self.code}).encode()
        lines = [f"HTTP/1.1 {self.status} {http.HTTPStatus(self.status).phrase}", "content-type: application/json",
                 f"content-length: {len(body)}", "connection: close",
                 *(f"{k.lower()}: {v}" for k, v in self.headers.items())]
        return ("\r\n".join(lines) + "\r\n\r\n").encode() + body


class LimitedHttpProtocol(HttpToolsProtocol):
    """uvicorn's httptools protocol with the limits of this module (bound by :func:`protocol_class`)."""

    limits: ConnectionLimits
    table: ConnectionTable

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.client_key: str | None = None
        self._counted = False
        self._in_head = False  # between a request's first byte and the end of its headers
        self._head_bytes = 0  # bytes received for a head still incomplete
        self._head_counted = 0  # bytes of the parsed request line and header lines
        self._header_lines = 0
        self._refusal: Refusal | None = None
        self._head_timer: asyncio.TimerHandle | None = None
        self._body_timer: asyncio.TimerHandle | None = None

    # connection
    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(transport)
        refusal = self.table.admit(self, self.client[0] if self.client else "")
        if refusal is not None:
            self._refuse(refusal)
            return
        self._counted = True
        self.table.set_waiting(self, True)
        self._head_timer = self.loop.call_later(self.limits.header_timeout_s, self._head_expired)

    def connection_lost(self, exc: Exception | None) -> None:
        self._cancel_timers()
        if self._counted:
            self._counted = False
            self.table.release(self)
        super().connection_lost(exc)

    def data_received(self, data: bytes) -> None:
        if self.transport.is_closing():
            return
        fresh = not self._in_head
        super().data_received(data)  # parses; the callbacks below raise a Refusal through send_400_response
        if self._in_head and not self.transport.is_closing():
            # A head begun in this chunk counts its parsed lines (the chunk may end a previous request), then
            # every chunk in full: the parser holds at most the cap plus one read
            self._head_bytes = self._head_counted if fresh else self._head_bytes + len(data)
            if self._head_bytes > self.limits.max_head:
                self._refuse(self._head_too_large())

    def send_400_response(self, msg: str) -> None:
        refusal, self._refusal = self._refusal, None
        self.table.refusing = False
        self._refuse(refusal or Refusal(400, "invalid_http", "the request is not valid HTTP/1.1"))

    def evict(self) -> None:
        """Close this connection (it waits without a request) to make room for a new one."""
        self.table.set_waiting(self, False)  # counted until it is gone, but never chosen twice
        self._cancel_timers()
        self.transport.close()

    # parser callbacks
    def on_message_begin(self) -> None:
        super().on_message_begin()
        self._in_head, self._head_bytes, self._head_counted, self._header_lines = True, 0, 0, 0
        if self._head_timer is None:
            self._head_timer = self.loop.call_later(self.limits.header_timeout_s, self._head_expired)

    def on_url(self, url: bytes) -> None:
        super().on_url(url)
        self._head_counted += len(url)
        if len(self.url) > self.limits.max_url:
            self._stop(Refusal(414, "url_too_long", f"the request URL is over {self.limits.max_url} bytes "
                               "(LASHSCOPE_MAX_URL_KB)"))

    def on_header(self, name: bytes, value: bytes) -> None:
        self._header_lines += 1
        self._head_counted += len(name) + len(value) + 4
        if self._header_lines > self.limits.max_headers:
            self._stop(Refusal(431, "too_many_headers", f"the request has over {self.limits.max_headers} header "
                               "lines (LASHSCOPE_MAX_HEADERS)"))
        if self._head_counted > self.limits.max_head:
            self._stop(self._head_too_large())
        super().on_header(name, value)

    def on_headers_complete(self) -> None:
        self._in_head = False
        if self._head_timer is not None:
            self._head_timer.cancel()
            self._head_timer = None
        self.table.set_waiting(self, False)
        super().on_headers_complete()
        self._body_timer = self.loop.call_later(self.limits.body_timeout_s, self._body_expired)

    def on_message_complete(self) -> None:
        if self._body_timer is not None:
            self._body_timer.cancel()
            self._body_timer = None
        super().on_message_complete()

    def on_response_complete(self) -> None:
        super().on_response_complete()
        if self._counted and not self.transport.is_closing() and not self.pipeline:
            self.table.set_waiting(self, True)

    # limits
    def _head_too_large(self) -> Refusal:
        return Refusal(431, "headers_too_large", f"the request line and headers are over {self.limits.max_head} "
                       "bytes (LASHSCOPE_MAX_HEADER_KB)")

    def _stop(self, refusal: Refusal) -> None:
        """Stop parsing (the parser wraps the exception into an error that lands in send_400_response)."""
        self._refusal = refusal
        self.table.refusing = True  # until send_400_response, right after uvicorn's warning
        raise refusal

    def _head_expired(self) -> None:
        self._head_timer = None
        if not self._in_head:
            self.transport.close()  # a connection that never sent a byte of a request
            return
        self._refuse(Refusal(408, "header_timeout", f"the request head did not arrive within "
                             f"{self.limits.header_timeout_s:g} s (LASHSCOPE_HEADER_TIMEOUT_S)"))

    def _body_expired(self) -> None:
        self._body_timer = None
        self._refuse(Refusal(408, "body_timeout", f"the request body did not arrive within "
                             f"{self.limits.body_timeout_s:g} s (LASHSCOPE_BODY_TIMEOUT_S)"))

    def _refuse(self, refusal: Refusal) -> None:
        """Answer ``refusal`` unless a response is under way on this connection, and close it. The running
        route, if any, sees the client gone: its reads end and what it still sends is dropped."""
        self._cancel_timers()
        cycle = self.cycle
        if cycle is not None and not cycle.response_complete:
            cycle.disconnected = True
            cycle.message_event.set()
            if cycle.response_started:
                self.transport.close()
                return
        log.debug("%s: %s", self.client, refusal.detail)
        self.transport.write(refusal.response())
        self.transport.close()

    def _cancel_timers(self) -> None:
        for timer in (self._head_timer, self._body_timer):
            if timer is not None:
                timer.cancel()
        self._head_timer = self._body_timer = None


def protocol_class(settings: Settings) -> type[LimitedHttpProtocol]:
    """A protocol class for ``uvicorn.run(http=...)`` enforcing ``settings``' limits, with its own table."""
    limits = ConnectionLimits.from_settings(settings)

    class BoundProtocol(LimitedHttpProtocol):
        pass

    BoundProtocol.limits = limits
    BoundProtocol.table = ConnectionTable(limits)
    logging.getLogger("uvicorn.error").addFilter(QuietRefusals(BoundProtocol.table))
    return BoundProtocol
