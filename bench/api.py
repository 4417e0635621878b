"""API benchmark: upload and analyse a 30-minute log; aligned-speed read latency under 20 clients.

Run: ``.venv/bin/python bench/api.py`` (about 2-3 minutes on 2 cores). Starts ``lashscope serve``
on a free loopback port with a fresh data directory, so nothing else shares the server.

Targets (issue 4): analysis of the 30-minute log <= 30 s; p95 of
``GET /analyses/{id}/speed?max_points=2000`` under 20 concurrent clients <= 150 ms.
The obvious alternative -- sending every point and letting the dashboard downsample -- is
timed in the same run and the ratio printed. Reads are measured twice: the same query
repeated (served from the response cache, as for many viewers of one dashboard) and every
request a different time window (each one downsampled from the memory-mapped arrays), and
with ``method=lttb``. Last, the per-request work in-process (downsampling and JSON number
formatting on the whole-log columns) next to the previous implementation, in the same run.
"""

from __future__ import annotations

import argparse
import http.client
import os
import statistics
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path
from typing import Any
from urllib.parse import urlencode, urlsplit

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.demo.build import build_demo_log  # noqa: E402
from app.demo.scenario import Scenario  # noqa: E402
from app.settings import default_dbc_dir  # noqa: E402
from tests.api.conftest import Server, create_vehicle, upload  # noqa: E402


def pct(values: list[float], q: float) -> float:
    s = sorted(values)
    return s[min(len(s) - 1, round(q / 100 * (len(s) - 1)))]


def hammer(url: str, clients: int, per_client: int, params_for: object,
           errors: Counter[int] | None = None) -> tuple[list[float], float]:
    """``clients`` threads, each with its own keep-alive connection, ``per_client`` GETs.

    The client is the standard library's ``http.client``: its per-request cost is a small
    fraction of httpx's, so the figures are the server's and not the load generator's (both
    share the same two cores). Returns latencies (ms) and the wall time (s). An answer other than 200
    raises, or is counted in ``errors`` by status when given.
    """
    parsed = urlsplit(url)
    lat: list[float] = []
    lock = threading.Lock()
    barrier = threading.Barrier(clients)

    def connect() -> http.client.HTTPConnection:
        return http.client.HTTPConnection(parsed.hostname or "127.0.0.1", parsed.port, timeout=120)

    def get(conn: http.client.HTTPConnection, params: dict[str, object]) -> http.client.HTTPConnection:
        try:
            conn.request("GET", f"{parsed.path}?{urlencode(params)}")
            resp = conn.getresponse()
        except (http.client.RemoteDisconnected, ConnectionResetError, BrokenPipeError):
            # the server closes keep-alive connections idle for 5 s (while others warm up): reconnect
            conn.close()
            conn = connect()
            conn.request("GET", f"{parsed.path}?{urlencode(params)}")
            resp = conn.getresponse()
        resp.read()
        if resp.status != 200:
            if errors is None:
                raise RuntimeError(f"GET {parsed.path} {params}: {resp.status}")
            with lock:
                errors[resp.status] += 1
        return conn

    def worker(k: int) -> None:
        mine = []
        conn = get(connect(), params_for(k, -1))  # type: ignore[operator]  # warm the connection
        barrier.wait()
        for i in range(per_client):
            t0 = time.perf_counter()
            conn = get(conn, params_for(k, i))  # type: ignore[operator]
            mine.append((time.perf_counter() - t0) * 1e3)
        conn.close()
        with lock:
            lat.extend(mine)

    threads = [threading.Thread(target=worker, args=(k,)) for k in range(clients)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return lat, time.perf_counter() - t0


def _previous_downsample(t: Any, cols: dict[str, Any], max_points: int) -> tuple[Any, dict[str, Any]]:
    """The previous implementation, kept here as the reference: argmax/argmin per bucket, then np.unique."""
    import numpy as np

    n = t.size
    per_bucket = 2 * len(cols)
    buckets = max(1, (max_points - 2) // per_bucket)
    size = int(np.ceil(n / buckets))
    full = n // size
    keep = [np.array([0, n - 1])]
    base = np.arange(full) * size
    for y in cols.values():
        whole = y[:full * size].reshape(full, size)
        keep += [base + np.argmax(whole, axis=1), base + np.argmin(whole, axis=1)]
        if n > full * size:
            keep.append(np.array([full * size + int(np.argmax(y[full * size:])),
                                  full * size + int(np.argmin(y[full * size:]))]))
    rows = np.unique(np.concatenate(keep))
    return t[rows], {k: y[rows] for k, y in cols.items()}


def _previous_json(a: Any, decimals: int) -> str:
    """The previous number formatting: one C-level % format over the array's Python floats."""
    import numpy as np

    finite = np.isfinite(a)
    body = (f"%.{decimals}f," * a.size)[:-1] % tuple(np.where(finite, a, np.nan).tolist())
    return f"[{body.replace('nan', 'null')}]"


def inprocess_breakdown(data_dir: Path, analysis_id: str, reps: int = 200) -> list[str]:
    """Per-request work on the whole-log columns, now and with the previous implementation, same run."""
    from app.analysis.downsample import BlockExtremes, downsample
    from app.api.numbers import json_numbers
    from app.storage.results import ResultCache
    from app.storage.sqlite import SQLiteStore

    store = SQLiteStore(data_dir)
    try:
        files = ResultCache().get(store.get_analysis(analysis_id).result_dir)
        t = files.array("whole_t")
        cols = {c: files.array(f"whole_{c}") for c in ("measured_rpm", "simulated_rpm", "torque_nm")}

        def per_call_ms(fn: Any) -> float:
            fn()
            t0 = time.perf_counter()
            for _ in range(reps):
                fn()
            return (time.perf_counter() - t0) / reps * 1e3

        arrays = list(cols.values())
        t_build = time.perf_counter()
        ext = BlockExtremes(arrays)
        build_ms = (time.perf_counter() - t_build) * 1e3
        new_ds = per_call_ms(lambda: ext.rows(arrays, 0, t.size - 1, 2000))
        scan_ds = per_call_ms(lambda: downsample(t, cols, 2000))
        old_ds = per_call_ms(lambda: _previous_downsample(t, cols, 2000))
        rows = ext.rows(arrays, 0, t.size, 2000)
        td, cd = t[rows], {k: v[rows] for k, v in cols.items()}
        new_js = per_call_ms(lambda: [json_numbers(td, 6), *(json_numbers(v, 3) for v in cd.values())])
        old_js = per_call_ms(lambda: [_previous_json(td, 6), *(_previous_json(v, 3) for v in cd.values())])
        lttb = per_call_ms(lambda: downsample(t, cols, 2000, "lttb"))
    finally:
        store.close()
    return [f"in-process, per request, whole log ({t.size} rows -> {td.size} rows, {reps} repetitions, same run):",
            f"  downsample min/max      {new_ds:6.2f} ms   previous (argmax + np.unique) {old_ds:6.2f} ms   "
            f"{old_ds / new_ds:4.1f}x  (block extremes, built once in {build_ms:.2f} ms; a full scan now: "
            f"{scan_ds:.2f} ms)",
            f"  JSON numbers (4 cols)   {new_js:6.2f} ms   previous (% format)          {old_js:6.2f} ms   "
            f"{old_js / new_js:4.1f}x",
            f"  downsample LTTB         {lttb:6.2f} ms   (method=lttb, 2000 rows)"]


def line(name: str, lat: list[float], wall: float) -> str:
    return (f"{name:<44} n={len(lat):>5}  p50={pct(lat, 50):7.1f} ms  p95={pct(lat, 95):7.1f} ms  "
            f"p99={pct(lat, 99):7.1f} ms  ({len(lat) / wall:6.0f} req/s)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--clients", type=int, default=20)
    ap.add_argument("--requests", type=int, default=50, help="per client")
    ap.add_argument("--log", type=Path, default=None, help="reuse (or create) the 30-minute log at this path")
    args = ap.parse_args()
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} (other work shares the cores)")

    with tempfile.TemporaryDirectory(prefix="lashscope-bench-") as tmp:
        tmpdir = Path(tmp)
        log = args.log or tmpdir / "drive30.blf"
        if not log.exists():
            t0 = time.perf_counter()
            dbc = default_dbc_dir()
            frames = build_demo_log(log, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml",
                                    Scenario(duration_s=args.minutes * 60.0))
            print(f"built {args.minutes:g}-minute log: {frames} frames, {log.stat().st_size / 2**20:.1f} MiB "
                  f"in {time.perf_counter() - t0:.1f} s (not part of the figures)")

        srv = Server(tmpdir / "data", max_upload_mb=1024).start()
        try:
            with httpx.Client(base_url=srv.url, timeout=600.0) as c:
                create_vehicle(c)
                t0 = time.perf_counter()
                r = upload(c, log)
                r.raise_for_status()
                up_s = time.perf_counter() - t0
                log_id = r.json()["id"]
                t0 = time.perf_counter()
                aid = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
                while (body := c.get(f"/analyses/{aid}").json())["status"] not in ("done", "failed"):
                    time.sleep(0.1)
                wall_s = time.perf_counter() - t0
                if body["status"] != "done":
                    print(f"analysis failed: {body['job']['error']}")
                    return 1
                from datetime import datetime

                job = body["job"]
                run_s = (datetime.fromisoformat(job["finished_at"]) -
                         datetime.fromisoformat(job["started_at"])).total_seconds()
                summ = body["summary"]
                print(f"upload (stream to disk, hash, validate {r.json()['frames']} frames): {up_s:.2f} s")
                print(f"analysis of the {args.minutes:g}-minute log: {run_s:.2f} s in the job "
                      f"({wall_s:.2f} s wall from POST to done); {summ['events']} events, "
                      f"{summ['with_metrics']} with metrics; target <= 30 s: {'PASS' if run_s <= 30 else 'FAIL'}")
                meta = c.get(f"/analyses/{aid}/metrics").json()["whole"]
                print(f"whole-log aligned series: {meta['points']} points per column")

            url = f"{srv.url}/analyses/{aid}/speed"
            n, k = args.requests, args.clients
            span = args.minutes * 60.0

            def same(_c: int, _i: int) -> dict[str, object]:
                return {"max_points": 2000}

            def varied(cl: int, i: int) -> dict[str, object]:
                t_a = (cl * 97.0 + i * 13.0) % (span - 120.0)  # a distinct 2-minute-plus window per request
                return {"max_points": 2000, "t0": round(t_a, 3), "t1": round(t_a + 120.0 + (i % 7), 3)}

            def whole_varied(cl: int, i: int) -> dict[str, object]:
                # the whole log, each request ending a different 10 ms earlier: never the same query twice
                return {"max_points": 2000, "t1": round(span - 0.01 * (1 + cl * 1000 + i), 3)}

            def full(cl: int, i: int) -> dict[str, object]:
                return {"max_points": 0, "t1": round(span - 0.01 * (1 + cl * 1000 + i), 3)}  # uncached too

            print(f"\nGET /analyses/{{id}}/speed, {k} concurrent clients x {n} requests, loopback:")
            lat_same, w = hammer(url, k, n, same)
            print(line("max_points=2000, whole log, same query", lat_same, w))
            lat_var, w = hammer(url, k, n, whole_varied)
            print(line("max_points=2000, whole log, uncached", lat_var, w))
            lat_win, w = hammer(url, k, n, varied)
            print(line("max_points=2000, 2-min windows, uncached", lat_win, w))

            def whole_lttb(cl: int, i: int) -> dict[str, object]:
                return {**whole_varied(cl, i), "method": "lttb"}

            lat_lttb, w = hammer(url, k, n, whole_lttb)
            print(line("max_points=2000, whole log, uncached, lttb", lat_lttb, w))
            lat_full, w = hammer(url, k, max(2, n // 25), full)
            print(line("alternative: every point, uncached", lat_full, w))
            p95 = pct(lat_var, 95)
            print(f"\np95 uncached whole-log read with max_points=2000: {p95:.1f} ms; target <= 150 ms: "
                  f"{'PASS' if p95 <= 150 else 'FAIL'}")
            print(f"ratio p95 every-point / max_points (uncached): {pct(lat_full, 95) / p95:.1f}x; "
                  f"median bytes per response: {len(httpx.get(url, params={'max_points': 2000}).content)} vs "
                  f"{len(httpx.get(url, params={'max_points': 0}, timeout=120).content)}")
            print(f"(median, same query: {statistics.median(lat_same):.1f} ms; load average now "
                  f"{os.getloadavg()[0]:.1f})")
            print()
            print("\n".join(inprocess_breakdown(tmpdir / "data", aid)))
        finally:
            srv.stop()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
