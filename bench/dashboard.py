"""Dashboard benchmark: first paint of the analysis view and zoom round trips on a 30-minute log.

Run: ``nice -n 5 .venv/bin/python bench/dashboard.py`` (a few minutes on 2 cores; needs Debian's chromium
and playwright, as the browser tests). Builds a 30-minute drive with the demo tools, starts
``lashscope serve`` on a free loopback port with a fresh data directory, uploads and analyses the
log through the API (not timed), then in headless Chromium:

* **first paint**: a fresh browser context (empty cache) opens ``/#/analysis/<id>``; the time from
  navigation start to the first frame with the whole-log chart drawn with data (the page notes
  ``performance.now()`` in the animation frame after the chart's draw), and to the whole view
  ready (events, metrics table, first page of overlays). The alternative timed beside it: the
  page fetching every whole-log row (``max_points=0``) and parsing it, what a dashboard without
  server-side downsampling does before it can draw.
* **zoom round trip**: the time from setting a new time window on the chart to the finer rows
  fetched (``max_points`` for the chart width), the chart redrawn and the next frame painted;
  random windows of 5 s to 5 min.
* **where the first paint goes**: each request of it from Resource Timing (when it left, time to
  first byte, the service's own time from its ``Server-Timing`` header, when it ended, body and
  wire bytes), the page's ``performance.mark`` points (modules run, layout, status read, rows
  parsed, chart drawn, next frame; medians and load by load) and ``JSON.parse`` of each answer.
* **largest response** of every request the views made (analysis view, zooms, overlay pages,
  ``/docs``), as sent (gzip-compressed where the browser accepts it), and what gzip levels 1, 6
  and 9 cost and save on the largest API answers.

* **a channel added** from the channel browser: the time from ticking a decoded channel to the chart
  redrawn with it on its unit's axis and the next frame painted (its rows fetched for the window
  shown with ``max_points``); beside it, the obvious alternative: fetching and parsing every row
  of that channel (``max_points=0``).
* **diagnosis view first paint**: a diagnosis of the same log (one candidate effect; not timed),
  then cold loads of ``/#/diagnosis/<id>``: navigation start to the first frame with the decision
  headline and every chart drawn (residual by event, phase and band; held-out overlays).

Targets: first paint <= 1 s on loopback; zoom round trip p95 <= 200 ms; no response over 2 MB;
a channel added <= 300 ms; diagnosis view first paint <= 1.5 s.
"""

from __future__ import annotations

import argparse
import gzip
import os
import random
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from app.demo.build import build_demo_log  # noqa: E402
from app.demo.scenario import Scenario  # noqa: E402
from app.settings import default_dbc_dir  # noqa: E402
from bench.api import pct  # noqa: E402
from tests.api.conftest import Server, create_vehicle, upload  # noqa: E402

ZOOM = """async ([t0, t1]) => {
  const el = document.querySelector('#timeline');
  const loads = Number(el.dataset.loads);
  const start = performance.now();
  el.chart.setScale('x', {min: t0, max: t1});
  while (Number(el.dataset.loads) === loads) await new Promise(r => setTimeout(r, 1));
  await new Promise(requestAnimationFrame);
  return performance.now() - start;
}"""

BREAKDOWN = """() => {
  const painted = Number(document.querySelector('#timeline').dataset.paintedMs);
  const nav = performance.getEntriesByType('navigation')[0];
  const app = (r) => { const s = (r.serverTiming || []).find((x) => x.name === 'app'); return s ? s.duration : null; };
  const row = (r) => ({name: r.name, start: r.startTime, ttfb: r.responseStart - r.requestStart, end: r.responseEnd,
    bytes: r.encodedBodySize, wire: r.transferSize, decoded: r.decodedBodySize, server: app(r)});
  return {painted, nav: {...row(nav), name: 'document', dcl: nav.domContentLoadedEventEnd},
          res: performance.getEntriesByType('resource').filter((r) => r.startTime < painted).map(row),
          marks: Object.fromEntries(performance.getEntriesByType('mark').map((m) => [m.name, m.startTime]))};
}"""

PARSE = """async (urls) => {
  const out = {};
  for (const url of urls) {
    const text = await (await fetch(url, {cache: 'no-store'})).text();
    const ms = [];
    for (let i = 0; i < 5; i++) { const s = performance.now(); JSON.parse(text); ms.push(performance.now() - s); }
    out[url] = ms.sort((a, b) => a - b)[2];
  }
  return out;
}"""

FETCH_PARSE = """async (url) => {
  const start = performance.now();
  const body = await (await fetch(url)).json();
  return [performance.now() - start, body.points];
}"""


ADD_CHANNEL = """async (name) => {
  const el = document.querySelector('#timeline');
  const series = Number(el.dataset.series);
  const start = performance.now();
  document.querySelector(`#channel-list input[data-channel='${name}']`).click();
  while (Number(el.dataset.series) === series) await new Promise(r => setTimeout(r, 1));
  await new Promise(requestAnimationFrame);
  return performance.now() - start;
}"""


def diagnosed(srv: Server, aid: str) -> str | None:
    """A diagnosis of the analysis with one candidate effect (not timed); None when it did not finish."""
    with httpx.Client(base_url=srv.url, timeout=600.0) as c:
        did: str = c.post(f"/analyses/{aid}/diagnoses", json={"candidates": ["backlash"]}).json()["id"]
        t = time.monotonic()
        while (doc := c.get(f"/diagnoses/{did}").json())["status"] in ("queued", "running"):
            time.sleep(1.0)
        decided = f" {doc['report']['decision']['status']}" if doc["status"] == "done" else ""
        print(f"diagnosed in {time.monotonic() - t:.0f} s: {doc['status']}{decided} (not part of the figures)")
        return did if doc["status"] == "done" else None


def channel_and_diagnosis(browser: Any, srv: Server, aid: str, page: Any, loads: int) -> None:
    """Channels added to the open analysis view, then cold first paints of the diagnosis view."""
    names = [n for n in ("wheel_speed_fl_rpm", "vehicle_speed_kmh", "brake", "wheel_speed_rr_rpm", "brake_pressed")
             if page.query_selector(f"#channel-list input[data-channel='{n}']")]
    page.evaluate("document.querySelector('#full-view').click()")
    page.wait_for_timeout(500)
    lat = [page.evaluate(ADD_CHANNEL, n) for n in names]
    mp = min(4000, page.evaluate("document.querySelector('#timeline').chart.width") * 2)
    bounded, every = [], []
    for i, n in enumerate(names):
        url = f"{srv.url}/analyses/{aid}/signals/{n}?t1={1e6 + i}"  # t1: an answer of its own, not cached
        bounded.append(page.evaluate(FETCH_PARSE, f"{url}&max_points={mp}")[0])
        every.append(page.evaluate(FETCH_PARSE, f"{url}&max_points=0")[0])
    print(f"\na channel added to the whole-log chart (tick -> rows fetched, chart rebuilt with its axis, next frame), "
          f"{', '.join(names)}:")
    print(f"median {statistics.median(lat):6.0f} ms   max {max(lat):6.0f} ms   target <= 300 ms: "
          f"{'PASS' if max(lat) <= 300 else 'FAIL'}   (each: {', '.join(f'{x:.0f}' for x in lat)})")
    print(f"a channel's read in the page (fetch + JSON parse): max_points={mp} "
          f"median {statistics.median(bounded):5.0f} ms; "
          f"alternative, every row median {statistics.median(every):5.0f} ms: "
          f"{statistics.median(every) / statistics.median(bounded):.1f}x")
    did = diagnosed(srv, aid)
    if did is None:
        print("diagnosis view: not measured (the diagnosis did not finish)")
        return
    paint = []
    for _ in range(loads):
        ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
        pg = ctx.new_page()
        pg.goto(f"{srv.url}/#/diagnosis/{did}")
        pg.wait_for_selector("main[data-painted-ms]", state="attached", timeout=120_000)
        paint.append(float(pg.get_attribute("main", "data-painted-ms") or "nan"))
        panels = pg.get_attribute("#diagnosis-overlays", "data-panels")
        ctx.close()
    print(f"\ndiagnosis view, new browser context each (empty cache), n={loads}, {panels} held-out overlays:")
    print(f"first paint (decision and every chart drawn)   median {statistics.median(paint):7.0f} ms   "
          f"max {max(paint):7.0f} ms   target <= 1500 ms: {'PASS' if max(paint) <= 1500 else 'FAIL'}   "
          f"(each, in order: {', '.join(f'{x:.0f}' for x in paint)})")


def analysed_log(srv: Server, log: Path) -> str:
    with httpx.Client(base_url=srv.url, timeout=600.0) as c:
        create_vehicle(c)
        r = upload(c, log)
        r.raise_for_status()
        aid: str = c.post("/analyses", json={"log_id": r.json()["id"], "vehicle": "ev"}).json()["id"]
        while (body := c.get(f"/analyses/{aid}").json())["status"] not in ("done", "failed"):
            time.sleep(0.2)
        if body["status"] != "done":
            raise SystemExit(f"analysis failed: {body['job']['error']}")
        s = body["summary"]
        print(f"analysed: {s['events']} events, {s['with_metrics']} with metrics (not part of the figures)")
        return aid


def _key(url: str, aid: str) -> str:
    return url.split("/", 3)[-1].replace(aid, "{id}") or "/"


def print_breakdown(samples: list[dict[str, Any]], parse: dict[str, float], aid: str) -> None:
    """Median timeline of the first paint over the cold loads: requests, the page's marks, JSON parse."""
    med = statistics.median
    rows: dict[str, list[dict[str, Any]]] = {}
    for smp in samples:
        for r in [smp["nav"], *smp["res"]]:
            rows.setdefault("/ (document)" if r is smp["nav"] else _key(r["name"], aid), []).append(r)
    print(f"\nwhere the first paint goes (median of {len(samples)} cold loads; ms since navigation start; "
          "ttfb = request sent -> first byte; server = the service's own time, Server-Timing):")
    print(f"  {'request':58s} {'start':>6s} {'ttfb':>6s} {'server':>6s} {'end':>6s} {'body B':>9s} {'wire B':>9s}")
    for name, rs in sorted(rows.items(), key=lambda kv: med([r["start"] for r in kv[1]])):
        srv = [r["server"] for r in rs if r["server"] is not None]
        print(f"  {name[:58]:58s} {med([r['start'] for r in rs]):6.0f} {med([r['ttfb'] for r in rs]):6.1f} "
              f"{(f'{med(srv):6.1f}' if srv else '     -')} {med([r['end'] for r in rs]):6.0f} "
              f"{med([r['decoded'] for r in rs]):9.0f} {med([r['wire'] for r in rs]):9.0f}")
    marks = [("DOMContentLoaded", [smp["nav"]["dcl"] for smp in samples])]
    for m, label in (("route", "route"), ("analysis:render", "render"), ("analysis:layout", "layout"),
                     ("analysis:record", "analysis record read (results done)"),
                     ("analysis:series", "whole-log rows fetched + parsed"),
                     ("chart:timeline:draw", "chart draw starts"), ("chart:timeline:drawn", "chart drawn"),
                     ("chart:timeline:inked", "drawn pixels counted"), ("analysis:drawn", "chart built")):
        marks.append((label, [smp["marks"][m] for smp in samples if m in smp["marks"]]))
    marks.append(("painted (next frame)", [smp["painted"] for smp in samples]))
    print("  page: " + ";  ".join(f"{label} {med(v):.0f}" for label, v in marks if v))
    every = [v for _, v in marks if len(v) == len(samples)]
    print("  the same, load by load: " + "  |  ".join(" ".join(f"{v[i]:.0f}" for v in every)
                                                    for i in range(len(samples))))
    print("  API requests load by load (server ms / end ms): " + "  |  ".join(
        " ".join(f"{r['server'] or 0:.1f}/{r['end']:.0f}" for r in smp["res"] if "/static/" not in r["name"])
        for smp in samples))
    print("  JSON.parse in the page (median of 5): " + ";  ".join(
        f"{_key(u, aid).split('?')[0]} {ms:.2f} ms" for u, ms in parse.items()))


def gzip_costs(srv: Server, aid: str, max_points: int) -> None:
    """What gzip costs and saves on the largest API answers (the service sends level 1)."""
    print("\ngzip of the largest API answers (median of 3 compressions, this machine):")
    with httpx.Client(base_url=srv.url, timeout=120.0, headers={"Accept-Encoding": "identity"}) as c:
        for path in (f"/analyses/{aid}/metrics", f"/analyses/{aid}/speed?max_points={max_points}",
                     f"/analyses/{aid}/speed?max_points=0"):
            body = c.get(path).content
            cells = []
            for level in (1, 6, 9):
                ms = []
                for _ in range(3):
                    t = time.perf_counter()
                    n = len(gzip.compress(body, compresslevel=level))
                    ms.append((time.perf_counter() - t) * 1e3)
                cells.append(f"level {level}: {n / 1024:7.0f} KiB {statistics.median(ms):6.1f} ms")
            print(f"  {_key(path, aid)[:40]:40s} {len(body) / 1024:7.0f} KiB -> " + ";  ".join(cells))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--loads", type=int, default=5, help="cold first paints")
    ap.add_argument("--zooms", type=int, default=40)
    ap.add_argument("--log", type=Path, default=None, help="reuse (or create) the log at this path")
    ap.add_argument("--no-diagnosis", action="store_true", help="skip the channel and diagnosis view figures")
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    chromium = os.environ.get("LASHSCOPE_CHROMIUM") or shutil.which("chromium")
    if not chromium:
        print("chromium not found (apt-get install chromium)")
        return 2
    print(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} (other work shares the cores)")
    with tempfile.TemporaryDirectory(prefix="lashscope-dash-") as tmp:
        tmpdir = Path(tmp)
        log = args.log or tmpdir / "drive.blf"
        if not log.exists():
            dbc = default_dbc_dir()
            frames = build_demo_log(log, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml",
                                    Scenario(duration_s=args.minutes * 60.0))
            print(f"built {args.minutes:g}-minute log: {frames} frames (not part of the figures)")
        srv = Server(tmpdir / "data", max_upload_mb=1024).start()
        sizes: list[tuple[int, str]] = []
        try:
            aid = analysed_log(srv, log)
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=chromium, args=["--no-sandbox"])
                paint, ready, every, bounded = [], [], [], []
                samples: list[dict[str, Any]] = []
                parse: dict[str, float] = {}
                page: Any = None
                warm = browser.new_context()  # the browser's own start-up is not the page's first paint
                warm.new_page().goto(f"{srv.url}/#/logs")
                warm.close()
                for i in range(args.loads):
                    ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
                    page = ctx.new_page()
                    page.on("response", lambda r: sizes.append((int(r.headers.get("content-length", -1)), r.url)))
                    page.goto(f"{srv.url}/#/analysis/{aid}")
                    page.wait_for_selector("#timeline[data-painted-ms]", state="attached", timeout=120_000)
                    paint.append(float(page.get_attribute("#timeline", "data-painted-ms")))
                    samples.append(page.evaluate(BREAKDOWN))
                    page.wait_for_selector("main[data-state='ready']", timeout=120_000)
                    page.wait_for_function("document.querySelector('#overlays').dataset.ready == '1'")
                    ready.append(page.evaluate("performance.now()"))
                    # what the chart's first read costs in the page, and the same with every row (uncached)
                    mp = page.evaluate("document.querySelector('#timeline').chart.width") * 2
                    ms, rows_b = page.evaluate(FETCH_PARSE, f"{srv.url}/analyses/{aid}/speed?max_points={min(4000, mp)}"
                                                            f"&t1={1e6 + i}")
                    bounded.append(ms)
                    ms, rows = page.evaluate(FETCH_PARSE, f"{srv.url}/analyses/{aid}/speed?max_points=0&t1={1e6 + i}")
                    every.append(ms)
                    if i == args.loads - 1:
                        parse = page.evaluate(PARSE, [r["name"] for r in samples[-1]["res"]
                                                      if "/static/" not in r["name"]])
                    else:
                        ctx.close()
                print(f"\nanalysis view of the {args.minutes:g}-minute log, new browser context each (empty cache), "
                      f"n={args.loads}:")
                print(f"first paint (whole-log chart drawn)   median {statistics.median(paint):7.0f} ms   "
                      f"max {max(paint):7.0f} ms   target <= 1000 ms: {'PASS' if max(paint) <= 1000 else 'FAIL'}   "
                      f"(each, in order: {', '.join(f'{x:.0f}' for x in paint)})")
                print(f"whole view ready (tables, overlays)   median {statistics.median(ready):7.0f} ms   "
                      f"max {max(ready):7.0f} ms")
                print(f"whole-log read in the page (fetch + JSON parse): max_points={min(4000, mp)} "
                      f"({rows_b} rows) median {statistics.median(bounded):5.0f} ms; alternative, every row "
                      f"({rows} rows) median {statistics.median(every):5.0f} ms: "
                      f"{statistics.median(every) / statistics.median(bounded):.1f}x")
                print_breakdown(samples, parse, aid)
                t_end = float(page.get_attribute("#timeline", "data-t1"))
                rnd = random.Random(0)
                lat = []
                for _ in range(args.zooms):
                    w = rnd.uniform(5.0, 300.0)
                    a = rnd.uniform(0.0, t_end - w)
                    lat.append(page.evaluate(ZOOM, [a, a + w]))
                print(f"\nzoom round trip (window set -> finer rows fetched, redrawn, next frame), n={args.zooms}:")
                print(f"p50 {pct(lat, 50):6.1f} ms   p95 {pct(lat, 95):6.1f} ms   max {max(lat):6.1f} ms   "
                      f"target p95 <= 200 ms: {'PASS' if pct(lat, 95) <= 200 else 'FAIL'}")
                if not args.no_diagnosis:
                    channel_and_diagnosis(browser, srv, aid, page, args.loads)
                page.goto(f"{srv.url}/docs")
                page.wait_for_selector(".swagger-ui .opblock", timeout=60_000)
                browser.close()
            gzip_costs(srv, aid, min(4000, mp))
        finally:
            srv.stop()
    views = [(n, u) for n, u in sizes if "max_points=0" not in u]  # the every-row comparison is no view
    print(f"\nlargest responses of {len(views)} (views, zooms, /docs; bytes sent, gzip-compressed where accepted):")
    for n, url in sorted(views, reverse=True)[:3]:
        print(f"  {n / 2**20:6.2f} MiB  {url.split('/', 3)[-1][:90]}")
    unknown = sum(1 for n, _ in views if n < 0)
    if unknown:
        print(f"  ({unknown} streamed without Content-Length, not sized)")
    worst = max(n for n, _ in views)
    print(f"largest: {worst / 2**20:.2f} MiB; target <= 2 MiB: {'PASS' if worst <= 2 * 2**20 else 'FAIL'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
