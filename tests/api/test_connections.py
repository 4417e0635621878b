"""Connection-level limits on real sockets against the real server (``app/api/connections.py``):
request heads, head and body deadlines, keep-alive, connections per client and in total, forwarded addresses."""

from __future__ import annotations

import json
import logging
import resource
import socket
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from app.api.connections import HANDLE_RESERVE, client_key, fit_to_file_limit
from app.cli import main
from tests.api.sockets import connect, exchange, get, read_all, serving, status_of


def _error(reply: bytes, status: int, code: str) -> str:
    assert status_of(reply) == status, reply[:300]
    head, _, body = reply.partition(b"\r\n\r\n")
    assert b"connection: close" in head.lower() and b"content-type: application/json" in head.lower()
    doc = json.loads(body)
    assert doc["code"] == code, doc
    detail: str = doc["detail"]
    return detail


def test_request_heads_are_bounded(tmp_path: Path, caplog: pytest.LogCaptureFixture) -> None:
    with serving(tmp_path / "data", max_header_kb=8, max_headers=20, max_url_kb=1) as srv:
        port = srv.port
        ok = exchange(port, get(headers="".join(f"X-H{i}: {'v' * 300}\r\n" for i in range(18))))
        assert status_of(ok) == 200, ok[:300]  # 20 lines of 5.6 KiB: at the limits
        detail = _error(exchange(port, get(headers="X-A: b\r\n" * 19)), 431, "too_many_headers")
        assert "20 header lines" in detail and "LASHSCOPE_MAX_HEADERS" in detail
        _error(exchange(port, get(headers=f"X-A: {'b' * 9000}\r\n")), 431, "headers_too_large")
        # a header line that never ends: refused from the raw bytes, not held until it completes
        with connect(port) as s:
            s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\nX-A: ")
            with pytest.raises(OSError):
                for _ in range(1000):
                    s.sendall(b"b" * 1024)
                    time.sleep(0.005)
            assert "LASHSCOPE_MAX_HEADER_KB" in _error(read_all(s), 431, "headers_too_large")
        # a body ending in the same read as the next request's first bytes (pipelining) is not counted as head
        with connect(port) as s:
            body = b'{"pad": "' + b"p" * 20_000 + b'"}'
            s.sendall(b"POST /analyses HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: application/json\r\n"
                      + f"Content-Length: {len(body)}\r\n\r\n".encode() + body + b"GET /health HTTP/1.1\r\n")
            time.sleep(0.2)
            s.sendall(b"Host: 127.0.0.1\r\nConnection: close\r\n\r\n")
            replies = read_all(s)
            assert status_of(replies) == 422 and b"HTTP/1.1 200 OK" in replies, replies[:300]
        _error(exchange(port, get("/health?" + "q" * 2000)), 414, "url_too_long")
        assert "Invalid HTTP request" not in caplog.text  # a refusal is not logged as a malformed request
        _error(exchange(port, b"NOT HTTP AT ALL\r\n\r\n"), 400, "invalid_http")
        assert "Invalid HTTP request" in caplog.text
        assert httpx.get(f"{srv.url}/health").json()["status"] == "ok"


def test_heads_and_bodies_have_deadlines(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with serving(data, header_timeout_s=0.5, body_timeout_s=1.5) as srv:
        port = srv.port
        detail = _error(exchange(port, b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n"), 408, "header_timeout")
        assert "0.5 s" in detail and "LASHSCOPE_HEADER_TIMEOUT_S" in detail
        assert exchange(port, b"") == b""  # a connection that sends nothing is closed without an answer
        # slowloris: a header line every 0.2 s still has to finish within the deadline
        with connect(port) as s:
            s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            with pytest.raises(OSError):
                for i in range(50):
                    s.sendall(f"X-{i}: a\r\n".encode())
                    time.sleep(0.2)
            _error(read_all(s), 408, "header_timeout")

        # trickle: a byte every 0.2 s is far inside the idle limit (60 s) but not inside the body deadline
        for path, ctype in (("/analyses", "application/json"), ("/logs?filename=t.blf", "application/octet-stream")):
            with connect(port) as s:
                s.sendall(f"POST {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: {ctype}\r\n"
                          "Content-Length: 1000\r\n\r\n".encode())
                with pytest.raises(OSError):
                    for _ in range(100):
                        s.sendall(b"{")
                        time.sleep(0.2)
                assert "LASHSCOPE_BODY_TIMEOUT_S" in _error(read_all(s), 408, "body_timeout")
        deadline = time.monotonic() + 10
        while list((data / "tmp").iterdir()) and time.monotonic() < deadline:
            time.sleep(0.05)  # the upload route removes its partial file once it sees the client gone
        assert list((data / "tmp").iterdir()) == []
        r = httpx.post(f"{srv.url}/analyses", json={"log_id": "nope", "vehicle": "ev"})
        assert r.status_code == 404  # a body that arrives in time reaches the route


def _one_reply(s: socket.socket) -> bytes:
    """One whole answer on a kept-alive connection (head, then ``Content-Length`` bytes)."""
    data = b""
    while b"\r\n\r\n" not in data:
        chunk = s.recv(65536)
        assert chunk, data
        data += chunk
    head, _, body = data.partition(b"\r\n\r\n")
    length = int(next(line.split(b":", 1)[1] for line in head.split(b"\r\n")
                      if line.lower().startswith(b"content-length")))
    while len(body) < length:
        body += s.recv(65536)
    return head + b"\r\n\r\n" + body


def test_an_idle_kept_alive_connection_is_closed_after_the_keep_alive_time(tmp_path: Path) -> None:
    with serving(tmp_path / "data", keep_alive_s=1) as srv, connect(srv.port) as s:
        keep = b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n"
        s.sendall(keep)
        assert status_of(_one_reply(s)) == 200
        s.sendall(keep)  # the same connection serves the next request
        assert status_of(_one_reply(s)) == 200
        s.settimeout(4.0)  # idle: closed by the server after 1 s (uvicorn's own default would keep it 5 s)
        assert s.recv(65536) == b""


@pytest.fixture
def capped(tmp_path: Path) -> Iterator[int]:
    with serving(tmp_path / "data", max_client_connections=3, max_connections=8,
                 trusted_proxies=["127.0.0.9"]) as srv:
        yield srv.port


def test_connections_per_client(capped: int) -> None:
    held = [connect(capped, "127.0.0.2") for _ in range(3)]
    try:
        detail = _error(exchange(capped, get(), src="127.0.0.2"), 429, "too_many_connections")
        assert "127.0.0.2" in detail and "LASHSCOPE_MAX_CLIENT_CONNECTIONS" in detail
        assert status_of(exchange(capped, get())) == 200  # another client is served
        proxied = [connect(capped, "127.0.0.9") for _ in range(4)]  # a trusted proxy carries many clients
        assert status_of(exchange(capped, get(), src="127.0.0.9")) == 200
        for s in proxied:
            s.close()
    finally:
        for s in held:
            s.close()
    time.sleep(0.2)  # the server notices the closes
    assert status_of(exchange(capped, get(), src="127.0.0.2")) == 200


def test_connections_in_total_make_room(capped: int) -> None:
    held = [connect(capped, f"127.0.1.{i}") for i in range(8)]  # the server is full of connections sending nothing
    try:
        for i in range(3):  # each new client is served; the connection waiting longest is closed for it
            new = connect(capped, f"127.0.2.{i}")
            held.append(new)
            new.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")  # kept alive: the server stays full
            assert status_of(new.recv(4096)) == 200
            assert read_all(held[i]) == b""
        held[3].sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")  # the others stay open
        assert status_of(held[3].recv(4096)) == 200
    finally:
        for s in held:
            s.close()


def test_a_server_busy_with_requests_refuses_new_connections(tmp_path: Path) -> None:
    with serving(tmp_path / "data", max_connections=2) as srv:
        uploads = [connect(srv.port, f"127.0.3.{i}") for i in range(2)]
        try:
            for s in uploads:  # uploads under way: requests in progress, nothing to close for a newcomer
                s.sendall(b"POST /logs?filename=a.blf HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                          b"Content-Type: application/octet-stream\r\nContent-Length: 100000\r\n\r\n" + b"\0" * 1000)
            time.sleep(0.2)
            detail = _error(exchange(srv.port, get()), 503, "server_busy")
            assert "LASHSCOPE_MAX_CONNECTIONS" in detail
        finally:
            for s in uploads:
                s.close()
        time.sleep(0.2)
        assert status_of(exchange(srv.port, get())) == 200


def test_client_keys_and_the_file_limit() -> None:
    assert client_key("192.0.2.7") == "192.0.2.7"
    assert client_key("2001:db8::1") == client_key("2001:db8::ffff") == "2001:db8::/64"  # one subscriber's prefix
    assert client_key("2001:db8:0:1::1") != client_key("2001:db8::1")
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    assert fit_to_file_limit(100) == 100
    huge = fit_to_file_limit(10**9)  # never more connections than the process may open handles
    assert huge <= resource.getrlimit(resource.RLIMIT_NOFILE)[0] - HANDLE_RESERVE
    resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))


def test_forwarded_addresses_only_from_trusted_proxies(tmp_path: Path) -> None:
    records: list[str] = []

    class Collect(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record.getMessage())

    access = logging.getLogger("uvicorn.access")
    handler = Collect()
    access.addHandler(handler)
    try:
        with serving(tmp_path / "untrusted", client_rate_per_s=1, rate_burst_s=2) as srv:
            access.setLevel(logging.INFO)  # after the server's logging set-up
            codes = [status_of(exchange(srv.port, get("/logs", f"X-Forwarded-For: 198.51.100.{i}\r\n")))
                     for i in range(10)]
            assert codes[:2] == [200, 200] and codes.count(429) == 8  # forged addresses share the peer's bucket
            limited = exchange(srv.port, get("/logs", "X-Forwarded-For: 198.51.100.77\r\n"))
            assert "client 127.0.0.1 " in _error(limited, 429, "rate_limited")
        assert records and all(r.startswith("127.0.0.1:") for r in records), records[:3]
        records.clear()
        with serving(tmp_path / "trusted", client_rate_per_s=1, rate_burst_s=2, trusted_proxies=["127.0.0.1/8"]) as srv:
            access.setLevel(logging.INFO)
            codes = [status_of(exchange(srv.port, get("/logs", f"X-Forwarded-For: 198.51.100.{i}\r\n")))
                     for i in range(10)]
            assert codes == [200] * 10  # behind a trusted proxy each forwarded client has its own bucket
            assert status_of(exchange(srv.port, get("/logs"))) == 200
        assert [r.split(" ")[0] for r in records[:2]] == ["198.51.100.0:0", "198.51.100.1:0"]
    finally:
        access.removeHandler(handler)


def test_bad_settings_are_one_line(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    assert main(["serve", "--data-dir", str(tmp_path), "--trusted-proxy", "proxy.example"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [invalid_setting]: ") and "'proxy.example' is not an IP address" in err
    assert main(["serve", "--data-dir", str(tmp_path), "--header-timeout", "0"]) == 2
    assert "header_timeout_s" in capsys.readouterr().err

