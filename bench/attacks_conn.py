"""Connection-level attacks on a real ``lashscope serve`` (issue 27), run by ``bench/fuzz_api.py``.

Each attack runs against one server at the default limits (only the body deadline is shortened,
``--body-timeout``, so the trickle attack ends in seconds) while ``/health`` is asked every
0.2 s from another loopback address, and prints the server's peak RSS, peak open handles, the
files in ``tmp/`` (peak, and left 2 s after the attack), its CPU seconds, the statuses the
attack got, responses >= 500 and the slowest ``/health``:

- **headers**: 4 connections each sending header lines of 1 MiB (a request head of up to 1 GiB),
  reconnecting whenever the server cuts them off;
- **slowloris**: connections (5000; 100 per source address) sending a header line a second and
  reopening whenever the server closes or refuses them;
- **trickle**: uploads declaring 10 MiB and sending a byte every 2 s (inside the 60 s idle limit);
- **forged forwarded**: the same burst of reads twice from one address, with and without a
  rotating ``X-Forwarded-For``: the rate limit must count them alike.

Last, the legitimate load at the default limits: 30 clients on keep-alive connections reading
aligned-speed windows while a diagnosis runs (p95 and errors). Linux routes all of 127.0.0.0/8
to loopback, so the attackers are other addresses than the monitor and the readers (127.0.0.1).
``--conn-scale`` shrinks the counts (the short form, ``bench/fuzz_api.py --short`` in
``tests/api/test_attacks.py``, runs 0.05, with half the body deadline).

Targets: RSS < 1 GiB and every ``/health`` within 1 s through every attack; 0 files left in
``tmp/``; 0 responses >= 500; the legitimate load p95 <= 150 ms with 0 errors.
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import socket
import threading
import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from bench.api import hammer, pct
from tests.api.conftest import Server, create_vehicle, upload, wait_for
from tests.api.sockets import connect, read_all, status_of

BODY_TIMEOUT_S = 6.0
PAGE = os.sysconf("SC_PAGE_SIZE")
TICKS = os.sysconf("SC_CLK_TCK")


def add_arguments(ap: argparse.ArgumentParser) -> None:
    ap.add_argument("--conn-scale", type=float, default=1.0,
                    help="scale of the connection attacks' counts (CI: 0.05)")
    ap.add_argument("--conn-only", action="store_true", help="only the connection attacks and the legitimate load")
    ap.add_argument("--no-conn", action="store_true", help="leave the connection attacks out")


@dataclass
class Watch:
    """Samples the server process (RSS, handles, CPU, files in tmp/) and probes ``/health`` meanwhile."""

    srv: Server
    rss_mb: float = 0.0
    handles: int = 0
    tmp_files: int = 0
    health_ms: list[float] = field(default_factory=list)
    health_failed: int = 0
    _stop: threading.Event = field(default_factory=threading.Event)
    _probing: threading.Event = field(default_factory=threading.Event)

    def _pid(self) -> int:
        assert self.srv.proc is not None
        return self.srv.proc.pid

    def cpu_s(self) -> float:
        fields = Path(f"/proc/{self._pid()}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / TICKS

    def files_in_tmp(self) -> int:
        return len(list((self.srv.data_dir / "tmp").iterdir()))

    def _sample(self) -> None:
        while True:
            with contextlib.suppress(OSError):
                rss = int(Path(f"/proc/{self._pid()}/statm").read_text().split()[1]) * PAGE / 2**20
                self.rss_mb = max(self.rss_mb, rss)
                self.handles = max(self.handles, len(os.listdir(f"/proc/{self._pid()}/fd")))
                self.tmp_files = max(self.tmp_files, self.files_in_tmp())
            if self._stop.wait(0.1):
                return

    def _probe(self) -> None:
        """Ask ``/health`` every 0.2 s from a process of its own: the attacks' threads hold this one's interpreter
        lock for long stretches, which would count as the server's latency."""
        ctx = multiprocessing.get_context("spawn")
        results: multiprocessing.SimpleQueue[tuple[float, bool]] = ctx.SimpleQueue()
        stop, ready = ctx.Event(), ctx.Event()
        proc = ctx.Process(target=probe_health, args=(self.srv.url, stop, ready, results))
        proc.start()
        ready.wait(60)
        self._probing.set()
        self._stop.wait()
        stop.set()
        proc.join()
        while not results.empty():
            ms, ok = results.get()
            self.health_ms.append(ms)
            self.health_failed += not ok

    @contextlib.contextmanager
    def running(self) -> Iterator[Watch]:
        threads = [threading.Thread(target=self._sample), threading.Thread(target=self._probe)]
        for t in threads:
            t.start()
        self._probing.wait()
        try:
            yield self
        finally:
            self._stop.set()
            for t in threads:
                t.join()


def probe_health(url: str, stop: Any, ready: Any, results: Any) -> None:
    """``GET /health`` on a new connection every 0.2 s until ``stop``; (ms, answered 200) into ``results``."""
    with httpx.Client(base_url=url, timeout=5.0) as c:
        ready.set()
        while True:
            t0 = time.perf_counter()
            try:
                ok = c.get("/health", headers={"Connection": "close"}).status_code == 200
            except httpx.HTTPError:
                ok = False
            results.put(((time.perf_counter() - t0) * 1e3, ok))
            if stop.wait(0.2):
                return


def attack(srv: Server, name: str, fn: Callable[[], Counter[int]]) -> bool:
    """Run ``fn`` (returns the statuses the attack got, 0: no answer) under a :class:`Watch`; print one line;
    whether every target held."""
    watch = Watch(srv)
    with watch.running():
        cpu0, t0 = watch.cpu_s(), time.perf_counter()
        statuses = fn()
        wall, cpu = time.perf_counter() - t0, watch.cpu_s() - cpu0
    time.sleep(2.0)
    left = watch.files_in_tmp()
    worst = max(watch.health_ms, default=float("nan"))
    errors = sum(v for k, v in statuses.items() if k >= 500)
    print(f"{name:<17} {wall:6.1f} s  peak RSS {watch.rss_mb:6.0f} MiB  handles {watch.handles:5d}  tmp files "
          f"{watch.tmp_files:4d} (left {left})  CPU {cpu:5.1f} s  /health max {worst:6.0f} ms, "
          f"{watch.health_failed} failed  >=500: {errors}  statuses "
          + ", ".join(f"{k or 'no answer'}: {v}" for k, v in sorted(statuses.items())), flush=True)
    return (watch.rss_mb < 1024 and worst <= 1000 and watch.health_failed == 0 and left == 0 and errors == 0)


def _port(srv: Server) -> int:
    return int(srv.url.rsplit(":", 1)[1])


def _answer(s: socket.socket) -> int:
    with contextlib.suppress(OSError):
        s.settimeout(30)
        return status_of(read_all(s))
    return 0


def header_flood(srv: Server, conns: int, lines: int, seconds: float) -> Counter[int]:
    """``conns`` connections at once, each sending up to ``lines`` header lines of 1 MiB to ``GET /health``,
    reconnecting when cut off, for ``seconds``."""
    line = b"X-Pad: " + b"a" * (2**20) + b"\r\n"
    statuses: Counter[int] = Counter()
    lock = threading.Lock()
    end = time.monotonic() + seconds

    def one(i: int) -> None:
        while time.monotonic() < end:
            s = connect(_port(srv), f"127.0.3.{i % 250 + 1}")
            with contextlib.suppress(OSError):
                s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
                for _ in range(lines):
                    s.sendall(line)
                s.sendall(b"\r\n")
            code = _answer(s)
            s.close()
            with lock:
                statuses[code] += 1

    threads = [threading.Thread(target=one, args=(i,)) for i in range(conns)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return statuses


def slowloris(srv: Server, conns: int, addresses: int, seconds: float) -> Counter[int]:
    """Hold ``conns`` connections from ``addresses`` source addresses, each sending a header line a second
    and reopened as soon as the server closes it, for ``seconds``; statuses of what the server answered."""
    statuses: Counter[int] = Counter()
    port = _port(srv)

    def opened(i: int) -> socket.socket | None:
        try:
            s = connect(port, f"127.0.{4 + i % addresses // 250}.{i % addresses % 250 + 1}", timeout=1.0)
            s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
            s.setblocking(False)
            return s
        except OSError:
            statuses[0] += 1
            return None

    socks = [opened(i) for i in range(conns)]
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        tick = time.monotonic()
        for i, s in enumerate(socks):
            if s is not None:
                try:
                    s.sendall(b"X-a: b\r\n")
                    continue
                except BlockingIOError:
                    continue
                except OSError:  # closed by the server: read its answer, then reopen
                    with contextlib.suppress(OSError):
                        statuses[status_of(s.recv(4096))] += 1
                    s.close()
            socks[i] = opened(i)
        time.sleep(max(0.0, 1.0 - (time.monotonic() - tick)))
    for s in socks:
        if s is not None:
            s.close()
    return statuses


def trickle(srv: Server, conns: int, seconds: float) -> Counter[int]:
    """``conns`` uploads declaring 10 MiB that send a byte every 2 s until answered (or ``seconds``)."""
    port = _port(srv)
    socks = []
    for i in range(conns):
        s = connect(port, f"127.0.6.{i % 250 + 1}")
        s.sendall(b"POST /logs?filename=trickle.blf HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                  b"Content-Type: application/octet-stream\r\nContent-Length: 10485760\r\n\r\n")
        socks.append(s)
    statuses: Counter[int] = Counter()
    end = time.monotonic() + seconds
    while socks and time.monotonic() < end:
        for s in list(socks):
            try:
                s.sendall(b"\0")
            except OSError:
                s.settimeout(5)
                statuses[_answer(s)] += 1
                s.close()
                socks.remove(s)
        time.sleep(2.0)
    for s in socks:
        statuses[0] += 1
        s.close()
    return statuses


def forged(srv: Server, n: int) -> Counter[int]:
    """``n`` reads from one address, then ``n`` from another with a new ``X-Forwarded-For`` each; prints how
    many of each were rate-limited."""
    limited = []
    statuses: Counter[int] = Counter()
    for src, forge in (("127.0.7.1", False), ("127.0.7.2", True)):
        transport = httpx.HTTPTransport(local_address=src)
        with httpx.Client(base_url=srv.url, transport=transport, timeout=10.0) as c:
            got: Counter[int] = Counter()
            for i in range(n):
                headers = {"X-Forwarded-For": f"198.51.{i // 250 % 250}.{i % 250 + 1}"} if forge else {}
                got[c.get("/logs", headers=headers).status_code] += 1
        limited.append(got[429])
        statuses += got
    print(f"forged forwarded: {limited[0]} of {n} reads rate-limited without X-Forwarded-For, {limited[1]} of {n} "
          "with a new forged address each", flush=True)
    return statuses


def legit_load(srv: Server, c: httpx.Client, analysis_id: str, clients: int, per_client: int) -> bool:
    """``clients`` readers at the default limits while a diagnosis runs: p95 and errors."""
    r = c.post(f"/analyses/{analysis_id}/diagnoses", json={})
    assert r.status_code == 202, r.text
    did = r.json()["id"]
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline:  # until the diagnosis computes (its worker has imported everything)
        state = c.get(f"/diagnoses/{did}").json()
        if state["status"] != "queued" and (state["progress"] > 0 or state["status"] != "running"):
            break
        time.sleep(0.2)

    def window(k: int, i: int) -> dict[str, object]:
        t0 = (k * 7 + i * 3) % 30
        return {"max_points": 2000, "t0": t0, "t1": t0 + 8}

    errors: Counter[int] = Counter()
    lat, _ = hammer(f"{srv.url}/analyses/{analysis_id}/speed", clients, per_client, window, errors)
    r = c.get(f"/diagnoses/{did}")
    status = r.json()["status"] if r.status_code == 200 else f"unknown, {r.status_code}"
    p95 = pct(lat, 95)
    print(f"legitimate load: {clients} clients x {per_client} reads at the default limits while a diagnosis "
          f"runs (still {status} at the end): p95 {p95:.1f} ms, errors {sum(errors.values())} "
          + (f"({dict(errors)})" if errors else "") + f"; load average {os.getloadavg()[0]:.1f}", flush=True)
    return p95 <= 150.0 and not errors


def run(args: argparse.Namespace, work: Path, log: Path, clients: int = 30, per_client: int = 20) -> bool:
    """Every attack above on a fresh server, then the legitimate load; whether every target held."""
    scale = args.conn_scale
    body_s = BODY_TIMEOUT_S if scale >= 0.5 else BODY_TIMEOUT_S / 2  # the short form: the trickle ends sooner
    srv = Server(work / "conn-data", max_upload_mb=16.0, extra_args=("--body-timeout", str(body_s))).start()
    ok = True
    try:
        with httpx.Client(base_url=srv.url, timeout=120.0) as c:
            create_vehicle(c)
            log_id = upload(c, log).json()["id"]
            analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            assert wait_for(c, analysis_id, timeout=300.0)["status"] == "done"
            print(f"connection attacks (scale {scale:g}; default limits, body deadline {body_s:g} s; "
                  f"load average {os.getloadavg()[0]:.1f}):", flush=True)
            seconds = max(3.0, 15 * scale)
            ok &= attack(srv, "headers", lambda: header_flood(srv, 4, 1000, seconds))
            ok &= attack(srv, "slowloris", lambda: slowloris(srv, max(250, round(5000 * scale)),
                                                             max(2, round(50 * scale)), seconds))
            ok &= attack(srv, "trickle", lambda: trickle(srv, max(10, round(200 * scale)), 3 * body_s))
            ok &= attack(srv, "forged forwarded", lambda: forged(srv, max(200, round(4000 * scale))))
            time.sleep(max(2.0, 10.0 * scale))  # the rate buckets of 127.0.0.1 are untouched, but the server settles
            ok &= legit_load(srv, c, analysis_id, clients, per_client)
    finally:
        srv.stop()
    print(f"connection targets: {'all met' if ok else 'NOT MET'}", flush=True)
    return ok
