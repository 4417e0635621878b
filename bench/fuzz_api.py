"""Abuse benchmark: >= 10 000 fuzzed requests, stalled uploads and reads under a running job,
against a real ``lashscope serve`` on a loopback port; first the key and method attacks of
``bench/attacks_keys.py`` and the connection-level attacks of ``bench/attacks_conn.py``, each on a
server of its own (``--keys-only``, ``--conn-only``: only those; ``--no-conn``: without).

Run: ``.venv/bin/python bench/fuzz_api.py [--n 10000] [--seed 0]`` (several minutes on 2 cores);
``--short``: every part at a small scale, the slowest work attacks left out (CI runs it in
``tests/api/test_attacks.py``, about two minutes).

The work attacks of ``bench/attacks_work.py`` (compression bombs of each format, pathological
DBCs, drivelines and format descriptions, the signal-map proposal, gap sensitivity and
identification jobs with absurd input, repeated fields) run after the fuzzed requests, with the
CPU of the server's child processes; kill -9 mid-upload and mid-read only when that module runs
alone (``.venv/bin/python bench/attacks_work.py``).

Targets (issues 12 and 27): 0 responses >= 500 in >= 10 000 fuzzed requests (multipart, driveline
TOML, format descriptions, JSON bodies, query parameters, the newer routes; ``tests/api/fuzzing.py``,
replayable by seed); 0 files left in ``tmp/`` and 0 server handles open on them after the abuse;
server RSS under 1 GiB and ``/health`` within 1 s through every attack, 0 files written outside the
data directory, <= 10 s of CPU per request (server or child) or a job with its limits; the
legitimate load (30 clients reading while a diagnosis runs, default limits) p95 <= 150 ms with 0
errors; read p95 <= 150 ms with 30 clients while a tolerance job runs (next to the same reads with
no job: the ratio is the job's cost to readers). Each part prints the server's peak RSS, open
handles, temp files and CPU seconds; the last line says whether every target was met (exit 1 if not).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import socket
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path
from urllib.parse import urlsplit

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.demo.build import build_demo_log  # noqa: E402
from app.demo.scenario import Scenario  # noqa: E402
from app.settings import default_dbc_dir  # noqa: E402
from bench import attacks_conn, attacks_keys, attacks_work  # noqa: E402
from bench.api import hammer, pct  # noqa: E402
from sim import dump_toml, load_vehicle  # noqa: E402
from tests.api.conftest import Server, create_vehicle, upload, wait_for  # noqa: E402
from tests.api.fuzzing import requests  # noqa: E402

IDLE_S = 2.0


def fuzz(c: httpx.Client, seed: int, n: int, analysis_id: str, log_id: str) -> tuple[Counter[int], list[str], float]:
    statuses: Counter[int] = Counter()
    failures: list[str] = []
    t0 = time.perf_counter()
    for i, req in enumerate(requests(seed, n, dump_toml(load_vehicle("paper")), analysis_id, log_id)):
        try:
            r = c.request(req.method, req.path, params=req.params, headers=req.headers, content=req.content)
        except httpx.HTTPError as exc:  # a reset connection is a failure too (the server must answer)
            statuses[0] += 1
            failures.append(f"#{i} {req.describe()[:200]}: {type(exc).__name__}")
            continue
        statuses[r.status_code] += 1
        if r.status_code >= 500:
            failures.append(f"#{i} {req.describe()[:200]}: {r.status_code} {r.text[:200]}")
    return statuses, failures, time.perf_counter() - t0


def stalled_uploads(url: str, count: int) -> int:
    """``count`` uploads that send 1 KiB of a declared 10 MiB and then nothing; returns how many got 408."""
    parts = urlsplit(url)
    socks = []
    for i in range(count):  # from many loopback addresses: one address holds at most 64 connections
        s = socket.create_connection((parts.hostname or "127.0.0.1", parts.port or 80), timeout=IDLE_S + 30,
                                     source_address=(f"127.0.8.{i % 250 + 1}", 0))
        s.sendall(b"POST /logs?filename=stall.blf HTTP/1.1\r\nHost: 127.0.0.1\r\n"
                  b"Content-Type: application/octet-stream\r\nContent-Length: 10485760\r\n\r\n" + b"\0" * 1024)
        socks.append(s)
    got = 0
    for s in socks:
        try:
            head = s.recv(256)
            got += head.startswith(b"HTTP/1.1 408")
        except OSError:
            pass
        s.close()
    return got


def leaks(srv: Server) -> tuple[int, int]:
    """(files in tmp/, server handles open on tmp/)."""
    tmp = srv.data_dir / "tmp"
    assert srv.proc is not None
    handles = 0
    for fd in Path(f"/proc/{srv.proc.pid}/fd").iterdir():
        with contextlib.suppress(OSError):
            handles += os.readlink(fd).startswith(str(tmp))
    return len(list(tmp.iterdir())), handles


def guard_cost(data: Path, calls: int = 20_000) -> list[str]:
    """Microseconds per request the request guard adds, in-process, next to calling the app bare."""
    import asyncio
    from types import SimpleNamespace

    from app.api.security import RequestGuard
    from app.settings import Settings
    from app.storage.sqlite import SQLiteStore

    store = SQLiteStore(data)

    async def app(scope: object, receive: object, send: object) -> None:
        return None

    async def receive() -> dict[str, object]:
        return {"type": "http.request", "body": b'{"log_id": "x"}', "more_body": False}

    async def send(message: object) -> None:
        return None

    holder = SimpleNamespace(state=SimpleNamespace(store=store))
    base = [(b"host", b"127.0.0.1:8000")]

    async def timed(fn: object, scope: dict[str, object]) -> float:
        t0 = time.perf_counter()
        for _ in range(calls):
            await fn(dict(scope), receive, send)  # type: ignore[operator]
        return (time.perf_counter() - t0) / calls * 1e6

    def measure(name: str, method: str, headers: list[tuple[bytes, bytes]]) -> str:
        guard = RequestGuard(app, Settings(data_dir=data, key_rate_per_s=0))
        scope = {"type": "http", "method": method, "path": "/analyses", "headers": headers, "app": holder}
        bare = asyncio.run(timed(app, scope))
        guarded = asyncio.run(timed(guard, scope))
        return f"request guard, {name}: {guarded:.1f} us per request (the bare app call: {bare:.2f} us)"

    json_type = (b"content-type", b"application/json"), (b"content-length", b"15")
    lines = [measure("no keys, GET", "GET", base), measure("no keys, POST JSON", "POST", [*base, *json_type])]
    auth = (b"authorization", f"Bearer {store.create_key('write')[1]}".encode())
    lines += [measure("with a key, GET", "GET", [*base, auth]),
              measure("with a key, POST JSON", "POST", [*base, auth, *json_type])]
    store.close()
    return lines


def abuse(c: httpx.Client, srv: Server, seed: int, n: int, stalled: int, analysis_id: str, log_id: str,
          short: bool = False) -> bool:
    """The fuzzed requests, the stalled uploads and the work attacks; prints the statuses and what was left behind;
    whether every target held."""
    statuses, failures, wall = fuzz(c, seed, n, analysis_id, log_id)
    print(f"fuzzed requests: {n} (seed {seed}) in {wall:.1f} s; statuses "
          + ", ".join(f"{k}: {v}" for k, v in sorted(statuses.items())))
    bad = sum(v for k, v in statuses.items() if k >= 500 or k == 0)
    print(f"responses 500 or worse (or no response): {bad}")
    for line in failures[:10]:
        print("  " + line)

    t0 = time.perf_counter()
    timed_out = stalled_uploads(srv.url, stalled)
    print(f"stalled uploads: {stalled}, answered 408 upload_timeout: {timed_out} "
          f"({time.perf_counter() - t0:.1f} s, idle limit {IDLE_S:g} s)")
    time.sleep(1.0)
    files, handles = leaks(srv)
    print(f"after the abuse: files left in tmp/: {files}, server handles open on tmp/: {handles}")
    assert c.get("/health").json()["status"] == "ok"
    lines = attacks_work.run(srv, kill=False, short=short)  # the reads below keep this server
    for line in lines:
        print(line, flush=True)
    figures = attacks_work.worst(lines)
    print("work attacks, worst: " + ", ".join(f"{k} {v:g}" for k, v in figures.items()), flush=True)
    return not bad and not files and not handles and attacks_work.met(figures)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--stalled", type=int, default=200)
    ap.add_argument("--clients", type=int, default=30)
    ap.add_argument("--per-client", type=int, default=20, help="reads per client in each read measurement")
    ap.add_argument("--reads-only", action="store_true",
                    help="only the read p95 with and without a job (no fuzzing, stalled uploads or guard timing)")
    ap.add_argument("--flood", type=int, default=6000, help="wrong keys in the wrong-key flood")
    ap.add_argument("--huge", type=int, default=300, help="1 MiB wrong keys in the huge-token flood")
    ap.add_argument("--keys-only", action="store_true", help="only the key and method attacks")
    ap.add_argument("--short", action="store_true",
                    help="the short form CI runs (tests/api/test_attacks.py): --n 300 --stalled 20 --per-client 5 "
                         "--flood 200 --huge 20 --conn-scale 0.05, the slow work attacks left out, "
                         "LASHSCOPE_VALIDATE_CPU_S=2")
    attacks_conn.add_arguments(ap)
    args = ap.parse_args()
    if args.short:
        args.n, args.stalled, args.per_client, args.flood, args.huge, args.conn_scale = 300, 20, 5, 200, 20, 0.05
    ok = True
    work = Path(tempfile.mkdtemp(prefix="lashscope-fuzz-"))
    if not args.reads_only and not args.conn_only:
        failed = attacks_keys.run(work, args.flood, args.huge)
        if args.keys_only:
            return 1 if failed else 0
        ok &= not failed
    if not args.reads_only and not args.conn_only:
        for line in guard_cost(work / "guard", 2_000 if args.short else 20_000):
            print(line)
    log = work / "drive.blf"
    dbc = default_dbc_dir()
    build_demo_log(log, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml", Scenario(duration_s=40.0))
    if not args.no_conn and not args.reads_only:
        conn_ok = attacks_conn.run(args, work, log)
        if args.conn_only:
            return 0 if conn_ok else 1
        ok &= conn_ok
    if args.short:
        os.environ["LASHSCOPE_VALIDATE_CPU_S"] = "2"  # the bombs and backtracking reads stop sooner
    os.environ["LASHSCOPE_UPLOAD_IDLE_S"] = str(IDLE_S)
    os.environ["LASHSCOPE_MAX_QUEUED_JOBS"] = "4"  # fuzzed analyses must not queue the run into the next hour
    # the fuzzed requests and the 30 readers share one address: exercise the handlers and the read path, not the
    # per-client limit (the legitimate load at the default limits is bench/attacks_conn.py's, on its own server)
    os.environ["LASHSCOPE_CLIENT_RATE_PER_S"] = "0"
    srv = Server(work / "data", max_upload_mb=16.0).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=120.0) as c:
            create_vehicle(c)
            log_id = upload(c, log).json()["id"]
            analysis_id = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            assert wait_for(c, analysis_id, timeout=300.0)["status"] == "done"

            if not args.reads_only:
                ok &= abuse(c, srv, args.seed, args.n, args.stalled, analysis_id, log_id, args.short)

            while c.get("/health").json()["jobs"]["queued"] or c.get("/health").json()["jobs"]["running"]:
                time.sleep(1.0)  # the fuzzed analyses finish first: the next figures are the band job's alone
            speed = f"{srv.url}/analyses/{analysis_id}/speed"

            def window(k: int, i: int) -> dict[str, object]:
                t0 = (k * 7 + i * 3) % 30
                return {"max_points": 2000, "t0": t0, "t1": t0 + 8}

            idle, _ = hammer(speed, args.clients, args.per_client, window)
            r = c.post(f"/analyses/{analysis_id}/tolerance", params={"n": 2000, "seed": 3})
            assert r.status_code == 202, r.text
            deadline = time.monotonic() + 120.0  # until the job computes (its worker has imported everything)
            while time.monotonic() < deadline:
                state = c.get(f"/analyses/{analysis_id}/tolerance", params={"n": 2000, "seed": 3})
                if state.status_code != 202 or state.json()["progress"] > 0:
                    break
                time.sleep(0.1)
            busy, _ = hammer(speed, args.clients, args.per_client, window)
            state = c.get(f"/analyses/{analysis_id}/tolerance", params={"n": 2000, "seed": 3})
            print(f"read p95 with {args.clients} clients x {args.per_client} reads: {pct(idle, 95):.1f} ms idle, "
                  f"{pct(busy, 95):.1f} ms while a tolerance job runs (ratio {pct(busy, 95) / pct(idle, 95):.2f}; "
                  f"job still {'running' if state.status_code == 202 else 'done'} at the end; load average "
                  f"{os.getloadavg()[0]:.1f})")
            ok &= pct(busy, 95) <= 150.0
    finally:
        srv.stop()
    print(f"targets: {'all met' if ok else 'NOT MET'}", flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
