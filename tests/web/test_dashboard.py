"""The dashboard in a real Chromium against a real server: what a person sees.

One module-scoped flow uploads the demo drive through the Logs page (progress bar, XHR) and
starts its analysis from the page; the tests then read the analysis view, zoom it, page
through the per-event overlays, download the metrics CSV, diagnose, compare vehicle versions
and watch a live session -- and compare what the page shows with what the API answers.
"""

from __future__ import annotations

import itertools
import re
import subprocess
import sys
import threading
import time
from datetime import datetime
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlparse

import httpx
import pytest

from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.ingest.readers import open_log
from app.live.bus import BusConfig, BusLink
from app.live.loopback import LoopbackHub
from app.live.replay import Replayer
from app.settings import default_dbc_dir
from tests.api.conftest import Server
from tests.web.conftest import screenshot

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def demo_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled demo drive (the one ``lashscope demo`` builds): 90 s, 16 tip-ins, 16 tip-outs."""
    path = tmp_path_factory.mktemp("web-demo") / "lashscope-demo.blf"
    dbc = default_dbc_dir()
    build_demo_log(path, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml")
    return path


@pytest.fixture(scope="module")
def analysis_id(browser: Any, server: Server, demo_log: Path) -> str:
    """Upload through the Logs page, start the analysis with vehicle ``ev`` there, wait for the view."""
    context = browser.new_context(viewport={"width": 1400, "height": 1000})
    pg = context.new_page()
    pg.set_default_timeout(60_000)
    try:
        pg.goto(f"{server.url}/#/logs")
        pg.wait_for_selector("#upload-form")
        pg.set_input_files("#upload-file", str(demo_log))
        pg.fill("#upload-tz", "Europe/Berlin")  # the demo BLF records a local clock without a zone
        pg.click("#upload-button")
        pg.wait_for_function("document.querySelector('#upload-status')?.textContent.includes('stored as')")
        # the bar ends full, with the bytes sent
        assert pg.get_attribute("#upload-status .progress", "aria-valuenow") == "100"
        assert f"{demo_log.name}: " in (pg.text_content("#upload-status .progress") or "")
        status = pg.text_content("#upload-status") or ""
        log_id = re.search(r"log_[0-9a-f]{16}", status)
        assert log_id, status
        logs = httpx.get(f"{server.url}/logs").json()
        assert [lg["id"] for lg in logs] == [log_id.group(0)]
        assert logs[0]["start_time"].endswith("+00:00")  # stored in UTC, the zone named at upload
        assert f"{logs[0]['frames']} frames" in status
        row = pg.wait_for_selector(f"tr[data-log='{log_id.group(0)}']")
        row.query_selector("select.vehicle-select").select_option("ev")
        row.query_selector("button.analyse").click()
        pg.wait_for_url(re.compile(r"#/analysis/an_"))
        aid = pg.url.rsplit("/", 1)[1]
        pg.wait_for_selector("main[data-state='ready']", timeout=240_000)
        screenshot(pg, "analysis-view", full_page=True)
        return aid
    finally:
        context.close()


def api(server: Server, path: str) -> Any:
    r = httpx.get(f"{server.url}{path}", timeout=30.0)
    assert r.status_code == 200, r.text
    return r.json()


def open_analysis(page: Any, server: Server, aid: str) -> None:
    page.goto(f"{server.url}/#/analysis/{aid}")
    page.wait_for_selector("main[data-state='ready']", timeout=120_000)


def test_analysis_view_draws_the_log_and_lists_every_event(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    events = api(server, f"/analyses/{analysis_id}/events")
    metrics = api(server, f"/analyses/{analysis_id}/metrics")
    assert events["count"] == 32  # the demo drive: 16 tip-ins and 16 tip-outs
    tl = page.wait_for_selector("#timeline[data-inked]", state="attached")  # counted after the frame is shown
    assert int(tl.get_attribute("data-inked")) > 2000  # lines drawn in the plot area, not an empty frame
    whole = api(server, f"/analyses/{analysis_id}/speed?max_points=2000")
    assert int(tl.get_attribute("data-source-points")) == whole["source_points"]
    assert 500 < int(tl.get_attribute("data-points")) <= 4 * 2000
    assert len(page.query_selector_all("#events-table tbody tr")) == events["count"]
    assert len(page.query_selector_all("#metrics-table tbody tr")) == len(metrics["events"])
    # the log's clock zone was named at upload: absolute stamps are UTC, not "log clock"
    log = api(server, f"/logs/{api(server, f'/analyses/{analysis_id}')['log_id']}")
    start = datetime.fromisoformat(log["start_time"])
    summary = page.text_content("#summary") or ""
    assert f"{start:%Y-%m-%d %H:%M:%S} UTC" in summary and "log clock" not in summary
    info = page.text_content("#timeline-info") or ""
    assert f"({start:%Y-%m-%d} " in info and info.endswith(" UTC)"), info
    # the verdict a person reads is the API's
    assert metrics["tracking"]["verdict"] in (page.text_content("#tracking") or "")
    # excluded events say why in the table
    excluded = [e for e in events["events"] if not e["included"]]
    text = page.text_content("#events-table") or ""
    for e in excluded:
        assert f"excluded: {e['exclusion']}" in text


def test_zoom_fetches_finer_data_for_the_window(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    tl = page.query_selector("#timeline")
    points0, t0_0, t1_0 = (float(tl.get_attribute(k)) for k in ("data-points", "data-t0", "data-t1"))
    box = page.query_selector("#timeline .u-over").bounding_box()
    with page.expect_response(lambda r: "/speed?" in r.url and "t0=" in r.url) as resp:
        y = box["y"] + box["height"] / 2
        page.mouse.move(box["x"] + 0.40 * box["width"], y)
        page.mouse.down()
        page.mouse.move(box["x"] + 0.46 * box["width"], y, steps=5)
        page.mouse.up()
    q = parse_qs(urlparse(resp.value.url).query)
    t0, t1 = float(q["t0"][0]), float(q["t1"][0])
    assert 0 < t1 - t0 < 0.1 * (t1_0 - t0_0)
    assert int(q["max_points"][0]) <= 4000
    page.wait_for_function(f"document.querySelector('#timeline').dataset.t1 == '{t1}'")
    body = resp.value.json()
    assert body["t_s"][0] >= t0 and body["t_s"][-1] <= t1
    # finer: more rows per second of log than the whole-log view, and every source row in this short window
    assert body["points"] / (t1 - t0) > 5 * points0 / (t1_0 - t0_0)
    assert body["points"] == api(server, f"/analyses/{analysis_id}/speed?max_points={q['max_points'][0]}"
                                         f"&t0={q['t0'][0]}&t1={q['t1'][0]}")["points"]
    page.wait_for_selector("#timeline[data-inked]", state="attached")  # the zoomed draw, counted
    assert int(tl.get_attribute("data-inked")) > 500
    screenshot(page, "analysis-zoomed")


def test_every_event_has_an_overlay_and_the_shared_span_option_holds(page: Any, server: Server,
                                                                     analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    events = api(server, f"/analyses/{analysis_id}/events")["events"]
    with_series = [e["index"] for e in events if e["has_series"]]
    seen: list[int] = []
    number = 1
    while True:
        page.wait_for_function(f"(g => g.dataset.ready == '1' && g.dataset.page == '{number}' && "
                               "g.querySelectorAll('.panel .chart[data-inked]').length == Number(g.dataset.panels))"
                               "(document.querySelector('#overlays'))")
        panels = page.query_selector_all("#overlays .panel")
        seen += [int(p.get_attribute("data-event")) for p in panels]
        for p in panels:
            assert int(p.query_selector(".chart").get_attribute("data-inked")) > 200
        label = page.text_content("#overlay-page") or ""
        m = re.search(r"page (\d+) of (\d+)", label)
        assert m
        if m.group(1) == m.group(2):
            break
        page.click("#overlay-next")
        number += 1
    assert seen == with_series  # every event with a series, in order, none sampled away

    def spans() -> list[float]:
        page.wait_for_function("[...document.querySelectorAll('#overlays .panel .chart')].every(c => c.dataset.ySpan)")
        return [float(c.get_attribute("data-y-span")) for c in page.query_selector_all("#overlays .panel .chart")]

    own = spans()
    assert max(own) > 1.2 * min(own)  # each panel on its own scale by default
    page.check("#shared-y")
    page.wait_for_function("(g => g.dataset.shared == 'true' && g.dataset.ready == '1')"
                           "(document.querySelector('#overlays'))")
    shared = spans()
    assert max(shared) == pytest.approx(min(shared), rel=1e-6)
    # the span is the widest speed excursion of the page's events (as the API serves them) plus 10 %
    page_events = [int(p.get_attribute("data-event")) for p in page.query_selector_all("#overlays .panel")]
    widest = 0.0
    for i in page_events:
        s = api(server, f"/analyses/{analysis_id}/speed?event={i}&max_points=800")
        v = [x for x in s["measured_rpm"] + s["simulated_rpm"] if x is not None]
        widest = max(widest, max(v) - min(v))
    assert shared[0] == pytest.approx(1.1 * widest, rel=1e-6)
    screenshot(page, "overlays-shared-span")


def test_metrics_table_sorts_and_exports_the_apis_csv(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    metrics = api(server, f"/analyses/{analysis_id}/metrics")["events"]
    page.click("#metrics-table th[data-key='fluctuation_rpm.measured']")
    cells = page.query_selector_all("#metrics-table tbody tr td:nth-child(4)")
    shown = [float(c.text_content() or "nan") for c in cells]
    expected = sorted(round(m["measured"]["fluctuation_rpm"], 1) for m in metrics)
    assert shown == pytest.approx(expected, abs=0.051)
    page.click("#metrics-table th[data-key='fluctuation_rpm.measured']")  # again: descending
    first = float(page.text_content("#metrics-table tbody tr td:nth-child(4)") or "nan")
    assert first == pytest.approx(expected[-1], abs=0.051)
    with page.expect_download() as dl:
        page.click("#metrics-csv")
    text = Path(dl.value.path()).read_text(encoding="utf-8")
    r = httpx.get(f"{server.url}/analyses/{analysis_id}/metrics?format=csv")
    assert r.headers["content-type"].startswith("text/csv")
    assert text == r.text
    assert len(text.strip().splitlines()) == len(metrics) + 1
    with page.expect_download() as png:
        page.click("#png-timeline")
    assert Path(png.value.path()).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_diagnosis_page_shows_the_decision_in_words(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    page.select_option("#diagnose-candidates", "backlash")  # one candidate keeps the fit short
    page.click("#diagnose")
    page.wait_for_url(re.compile(r"#/diagnosis/an_"))
    did = page.url.rsplit("/", 1)[1]
    page.wait_for_selector("#decision", timeout=900_000)
    report = api(server, f"/diagnoses/{did}")["report"]
    decision = page.text_content("#decision") or ""
    assert report["decision"]["status"] in decision
    assert report["decision"]["reason"] in decision
    rows = page.query_selector_all("#candidates tbody tr")
    assert len(rows) == len(report["candidates"]) + len(report["pairs"])
    page.wait_for_selector("main[data-state='ready']")
    headline = page.text_content("#headline") or ""
    assert report["decision"]["status"] in headline and len(headline) < 200  # one line; the reason is below it
    _diagnosis_charts(page, server, did, report)
    if report["decision"]["status"] == "base_parameters":  # the vehicle file is off: no candidate is scored
        card = page.text_content("#base-parameters") or ""
        assert all(p["label"] in card for p in report["decision"]["base_parameters"])
    else:
        assert "backlash" in (page.text_content("#candidates") or "")
    if report["decision"]["status"] in ("explained", "partial", "ambiguous"):
        versions = len(api(server, "/vehicles/ev/versions"))
        page.click("#apply")
        page.wait_for_selector("#actions-result >> text=stored ev")
        assert len(api(server, "/vehicles/ev/versions")) == versions + 1
        assert f"stored ev v{versions + 1}" in (page.text_content("#actions-result") or "")
        page.click("#validate")  # on the only stored log: the demo drive itself
        page.wait_for_selector("#validation", timeout=900_000)
        val = api(server, f"/diagnoses/{did}")["validation"]
        assert f"{val['events']} events" in (page.text_content("#validation") or "")
        assert f"{100 * val['shrink']['value']:.1f} %" in (page.text_content("#validation") or "")
    screenshot(page, "diagnosis", full_page=True)
    assert page.console_errors == [] and page.hosts <= {"127.0.0.1", "blob", "data"}
    # an unknown diagnosis says so in the page
    page.goto(f"{server.url}/#/diagnosis/an_0123456789abcdef--dg00000000")
    page.wait_for_selector("main .error")
    assert "diagnosis_not_found" in (page.text_content("main .error") or "")


def test_vehicles_page_compares_two_versions_field_by_field(page: Any, server: Server) -> None:
    r = httpx.post(f"{server.url}/vehicles", data={"name": "ev", "preset": "single_reduction"})
    assert r.status_code in (200, 201), r.text
    latest = r.json()["version"]
    diff = api(server, f"/vehicles/ev/compare?a={latest - 1}&b={latest}")
    assert diff["changed"] > 0
    page.goto(f"{server.url}/#/vehicles")
    page.click("#vehicle-table tbody tr:has-text('ev') button")
    page.wait_for_selector("#compare-table")
    changed = page.query_selector_all("#compare-table tbody tr.changed")
    assert len(changed) == diff["changed"]
    first = next(f for f in diff["fields"] if f["changed"])
    assert first["field"] in (changed[0].text_content() or "")
    figures = page.query_selector_all("#compare-figures tbody tr")  # the engineering figures above the fields
    assert [f["key"] for f in diff["figures"]] == ["stiffness", "freq", "damping", "mass", "lash", "torque_gain"]
    assert len(figures) == 6 and "vehicle mass (kg)" in (figures[3].text_content() or "")
    mass = diff["figures"][3]
    assert f"{mass['ratio']:.3f}x" in (figures[3].text_content() or "")
    screenshot(page, "vehicles-compare")


def test_vehicles_page_registers_from_uploaded_files_and_a_proposed_map(page: Any, server: Server, analysis_id: str,
                                                                        tmp_path: Path) -> None:
    """The DBC and the driveline file go up through the page; the map is proposed from the stored log with its
    evidence, edited on the page, and registered with them."""
    from sim import dump_toml, load_vehicle

    driveline = tmp_path / "my-driveline.toml"
    driveline.write_text(dump_toml(load_vehicle("single_reduction")), encoding="utf-8")
    log_id = api(server, f"/analyses/{analysis_id}")["log_id"]
    page.goto(f"{server.url}/#/vehicles")
    page.wait_for_selector("#vehicle-form")
    page.fill("#vehicle-name", "from-log")
    page.set_input_files("#vehicle-dbc", str(default_dbc_dir() / "lashscope_ev.dbc"))
    page.set_input_files("#vehicle-driveline", str(driveline))
    page.select_option("#vehicle-log", log_id)
    page.fill("#vehicle-map-changes", "brake_pressed=-")
    page.click("#vehicle-propose")
    page.wait_for_selector("#proposal-table")
    table = page.text_content("#proposal-table") or ""
    assert "MCU_Speed.MotorSpeed" in table and "brake_pressed" not in table and "rate (Hz)" in table
    text = page.input_value("#vehicle-map")
    assert "[channels.motor_torque_nm]" in text and "[channels.vehicle_speed_kmh]" in text
    # edit on the page: drop the road speed
    head, _, rest = text.partition("[channels.vehicle_speed_kmh]")
    page.fill("#vehicle-map", head + rest.partition("\n\n")[2])
    page.click("#vehicle-register")
    page.wait_for_function("document.querySelector('#vehicle-msg')?.textContent.includes('stored from-log v1')")
    summary = api(server, "/vehicles/from-log")["summary"]
    assert "vehicle_speed_kmh" not in summary["channels"] and "brake_pressed" not in summary["channels"]
    assert summary["channels"]["motor_speed_rpm"] == "MCU_Speed.MotorSpeed"
    assert summary["vehicle"] == load_vehicle("single_reduction").name
    screenshot(page, "vehicles-register", full_page=True)


def test_live_page_shows_frames_arriving(page: Any, server: Server, hub_port: int, tmp_path: Path) -> None:
    drive = tmp_path / "live.blf"
    dbc = default_dbc_dir()
    build_demo_log(drive, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml", Scenario(duration_s=12.0))
    with LoopbackHub(port=hub_port) as hub:
        r = httpx.post(f"{server.url}/live/sessions", json={"interface": "tcp_loopback", "channel": hub.channel,
                                                            "vehicle": "ev"}, timeout=30.0)
        assert r.status_code == 201, r.text
        sid = r.json()["id"]
        page.goto(f"{server.url}/#/live/{sid}")
        page.wait_for_selector("#live-chart")
        time.sleep(1.0)  # the page's stream is subscribed before the replay starts
        link = BusLink(BusConfig("tcp_loopback", hub.channel))
        link.open()
        replay = threading.Thread(target=lambda: Replayer(link, lambda: open_log(drive).chunks(), rate=1.0).run(),
                                  daemon=True)
        replay.start()
        try:
            page.wait_for_function("Number(document.querySelector('#live-chart').dataset.samples) > 200",
                                   timeout=60_000)
            first = int(page.get_attribute("#live-chart", "data-updates") or 0)
            page.wait_for_function(f"Number(document.querySelector('#live-chart').dataset.updates) > {first + 5}")
            assert int(page.get_attribute("#live-chart", "data-inked") or 0) > 200
            assert "frames/s" in (page.text_content("#live-status") or "")
            replay.join(60)
            # events appear as they complete: the table holds what the session reports
            page.wait_for_function("document.querySelectorAll('#live-events tbody tr').length >= 2")
            deadline = time.monotonic() + 30
            while True:
                reported = api(server, f"/live/sessions/{sid}/events")["count"]
                rows = len(page.query_selector_all("#live-events tbody tr"))
                if rows == reported or time.monotonic() > deadline:
                    break
                time.sleep(0.5)
            assert rows == reported
            screenshot(page, "live")
            # a reload (or a page opened late) reads the session's history first: every event, newest first
            page.reload()
            page.wait_for_selector("main[data-state='ready']")
            page.wait_for_function(f"document.querySelectorAll('#live-events tbody tr').length >= {reported}")
            history = api(server, f"/live/sessions/{sid}/events")
            shown = [int(r.get_attribute("data-event")) for r in page.query_selector_all("#live-events tbody tr")]
            assert shown == sorted((e["index"] for e in history["events"]), reverse=True)
            assert "frames" in (page.text_content("#live-status") or "")
        finally:
            replay.join(60)
            link.close()
            httpx.post(f"{server.url}/live/sessions/{sid}/stop", timeout=60.0)
    status = api(server, f"/live/sessions/{sid}")
    assert status["frames_received"] == sum(len(c) for c in open_log(drive).chunks())
    page.goto(f"{server.url}/#/live/no_such_session")
    page.wait_for_selector("main .error")
    assert "no_such_session" in (page.text_content("main .error") or "")


def _drag(page: Any, selector: str, a: float, b: float) -> None:
    box = page.query_selector(selector).bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + a * box["width"], y)
    page.mouse.down()
    page.mouse.move(box["x"] + b * box["width"], y, steps=5)
    page.mouse.up()


CHART_COLUMN = """name => { const u = document.querySelector('#timeline').chart;
  const k = u.series.findIndex(s => s.label.split(' ')[0] === name);
  const t = [], v = [];
  u.data[k].forEach((x, i) => { if (x != null) { t.push(u.data[0][i]); v.push(x); } });
  return [t, v]; }"""


def test_channel_browser_plots_any_channel_on_its_units_axis(page: Any, server: Server, analysis_id: str) -> None:
    signals = api(server, f"/analyses/{analysis_id}/signals")["signals"]
    open_analysis(page, server, analysis_id)
    page.fill("#channel-search", "wheel")
    wheels = sorted(n for n in signals if "wheel" in n or "wheel" in signals[n]["unit"])
    assert len(wheels) == 4  # the reference DBC's four wheel speeds
    page.wait_for_function(f"document.querySelector('#channel-list').dataset.shown == '{len(wheels)}'")
    assert [e.get_attribute("data-channel") for e in page.query_selector_all("#channel-list input")] == wheels
    tl = page.query_selector("#timeline")
    series0, axes0 = int(tl.get_attribute("data-series")), int(tl.get_attribute("data-axes"))
    with page.expect_response(lambda r: "/signals/wheel_speed_fl_rpm?" in r.url) as resp:
        page.check("#channel-list input[data-channel='wheel_speed_fl_rpm']")
    page.wait_for_function(f"document.querySelector('#timeline').dataset.series == '{series0 + 1}'")
    assert int(tl.get_attribute("data-axes")) == axes0  # rpm: the motor speed's axis
    rows = resp.value.json()
    t, v = page.evaluate(CHART_COLUMN, "wheel_speed_fl_rpm")
    assert v == rows["wheel_speed_fl_rpm"] and t == rows["t_s"]  # the API's rows, each at its own time
    assert rows["source_points"] == signals["wheel_speed_fl_rpm"]["samples"]
    assert float(tl.get_attribute("data-channel-ms")) > 0
    page.fill("#channel-search", "km/h")  # by unit
    page.check("#channel-list input[data-channel='vehicle_speed_kmh']")
    page.wait_for_function(f"document.querySelector('#timeline').dataset.series == '{series0 + 2}'")
    assert int(tl.get_attribute("data-axes")) == axes0 + 1  # a new unit, a new axis
    assert page.url.endswith("/ch=wheel_speed_fl_rpm,vehicle_speed_kmh")
    page.wait_for_selector("#timeline[data-inked]", state="attached")
    screenshot(page, "analysis-channels")
    # the address keeps the channels: a reload plots them again
    page.reload()
    page.wait_for_selector("main[data-state='ready']")
    page.wait_for_function(f"document.querySelector('#timeline').dataset.series == '{series0 + 2}'")
    assert page.is_checked("#channel-list input[data-channel='vehicle_speed_kmh']")
    # unticked: gone from the chart and from the address
    page.uncheck("#channel-list input[data-channel='wheel_speed_fl_rpm']")
    page.wait_for_function(f"document.querySelector('#timeline').dataset.series == '{series0 + 1}'")
    assert page.url.endswith("/ch=vehicle_speed_kmh")
    assert page.console_errors == [] and page.hosts <= {"127.0.0.1", "blob", "data"}  # offline, no error


def test_a_missing_channel_says_so_and_the_chart_stays(page: Any, server: Server, analysis_id: str) -> None:
    page.goto(f"{server.url}/#/analysis/{analysis_id}/ch=no_such_channel")
    page.wait_for_selector("main[data-state='ready']", timeout=120_000)
    err = page.text_content("#channel-status .error") or ""
    assert "no_such_channel" in err and "signal_not_found" in err
    assert int(page.get_attribute("#timeline", "data-inked") or page.wait_for_selector(
        "#timeline[data-inked]", state="attached").get_attribute("data-inked")) > 2000


def test_two_cursors_read_every_series_and_the_delta(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    box = page.query_selector("#timeline .u-over").bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.click(box["x"] + 0.3 * box["width"], y)
    page.keyboard.down("Shift")
    page.mouse.click(box["x"] + 0.6 * box["width"], y)
    page.keyboard.up("Shift")
    page.wait_for_function("document.querySelector('#cursor-readout')?.dataset.b")
    a = float(page.get_attribute("#cursor-readout", "data-a") or "nan")
    b = float(page.get_attribute("#cursor-readout", "data-b") or "nan")
    tl = page.query_selector("#timeline")
    t0, t1 = float(tl.get_attribute("data-t0")), float(tl.get_attribute("data-t1"))
    assert a == pytest.approx(t0 + 0.3 * (t1 - t0), abs=0.01 * (t1 - t0))
    assert b == pytest.approx(t0 + 0.6 * (t1 - t0), abs=0.01 * (t1 - t0))
    text = page.text_content("#cursor-readout") or ""
    time_row = next(r for r in text.splitlines() if r.startswith("time (s)")).split()
    assert float(time_row[-1]) == pytest.approx(b - a, abs=2e-3)
    # each series' values at A and B are the chart's rows nearest the cursors, and B - A their difference
    meas = next(r for r in text.splitlines() if r.startswith("measured rpm")).split()
    va, vb, d = (float(x) for x in meas[-3:])
    assert d == pytest.approx(vb - va, abs=0.011)
    t, v = page.evaluate(CHART_COLUMN, "measured")
    near = min(range(len(t)), key=lambda i: abs(t[i] - a))
    assert va == pytest.approx(v[near], abs=0.006)
    assert page.is_visible("#timeline .u-over") and text.count("\n") >= 5  # time and every series


def test_overlays_follow_the_zoom_on_time_from_the_crossing(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    events = api(server, f"/analyses/{analysis_id}/events")["events"]
    page.wait_for_function("document.querySelector('#overlays')?.dataset.ready == '1'")
    # the panels' time axis is time from the torque zero crossing
    spans = page.evaluate("[...document.querySelectorAll('#overlays .panel .chart')].map(c => [c.chart.scales.x.min, "
                          "c.chart.scales.x.max])")
    assert spans and all(lo < 0 < hi for lo, hi in spans)
    # the whole-log chart's event labels never overlap
    boxes = page.evaluate("document.querySelector('#timeline').chart.labelBoxes")
    assert len(boxes) == len(events)
    for row in {b["row"] for b in boxes}:
        xs = sorted((b["x"], b["x"] + b["w"]) for b in boxes if b["row"] == row)
        assert all(x1 <= x0b for (_, x1), (x0b, _) in itertools.pairwise(xs))
    _drag(page, "#timeline .u-over", 0.30, 0.55)
    page.wait_for_function("document.querySelector('#overlays')?.dataset.focus && "
                           "document.querySelector('#overlays')?.dataset.ready == '1'")
    t0, t1 = (float(x) for x in (page.get_attribute("#overlays", "data-focus") or "").split(","))
    inside = [e["index"] for e in events if e["has_series"] and t0 <= e["t_cross_s"] <= t1]
    shown = [int(p.get_attribute("data-event")) for p in page.query_selector_all("#overlays .panel")]
    assert inside and shown == inside[:12]
    screenshot(page, "overlays-following-zoom")
    # and back: "in chart" on a panel zooms the whole-log chart to that event's window
    first = next(e for e in events if e["index"] == shown[0])
    page.click(f"#overlays .panel[data-event='{shown[0]}'] button.in-chart")
    page.wait_for_function(f"Math.abs(document.querySelector('#timeline').dataset.t0 - {first['t_start_s']}) < 1e-6")
    assert float(page.get_attribute("#timeline", "data-t1") or "nan") == pytest.approx(first["t_end_s"], abs=1e-6)


def test_metrics_columns_are_grouped_and_chosen(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    groups = [g.text_content() for g in page.query_selector_all("#metrics-table tr.group th")]
    assert "fluctuation peak-valley (rpm)" in groups and "aligned error" in groups
    assert page.query_selector("#metrics-table th[data-key='damping_ratio.measured']") is None
    page.click("#metrics-chooser summary")
    page.check("#metrics-chooser input[data-metric='damping_ratio']")
    page.uncheck("#metrics-chooser input[data-part='simulated']")
    page.wait_for_selector("#metrics-table th[data-key='damping_ratio.measured']")
    assert page.query_selector_all("#metrics-table th[data-key$='.simulated']") == []
    metrics = api(server, f"/analyses/{analysis_id}/metrics")["events"]
    page.click("#metrics-table th[data-key='damping_ratio.measured']")
    col = [h.get_attribute("data-key") for h in page.query_selector_all("#metrics-table thead tr:not(.group) th")]
    k = col.index("damping_ratio.measured") + 1
    shown = [c.text_content() for c in page.query_selector_all(f"#metrics-table tbody tr td:nth-child({k})")]
    expected = sorted(m["measured"]["damping_ratio"] for m in metrics if m["measured"].get("damping_ratio") is not None)
    assert [float(x) for x in shown[:len(expected)]] == pytest.approx(expected, abs=5.1e-4)
    # the choice is kept in this browser
    page.reload()
    page.wait_for_selector("main[data-state='ready']")
    assert page.query_selector("#metrics-table th[data-key='damping_ratio.measured']") is not None
    screenshot(page, "metrics-chooser")


def test_a_failed_analysis_says_why_in_the_list(page: Any, server: Server, tmp_path: Path) -> None:
    junk = tmp_path / "other-car.log"  # frames of an id the vehicle's DBC does not know
    junk.write_text("".join(f"({1 + 0.01 * i:.6f}) can0 7FF#00112233\n" for i in range(300)))
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        with junk.open("rb") as fh:
            log_id = c.post("/logs", files={"file": (junk.name, fh)}).json()["id"]
        aid = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
        deadline = time.monotonic() + 120
        while (rec := c.get(f"/analyses/{aid}").json())["status"] not in ("done", "failed"):
            assert time.monotonic() < deadline
            time.sleep(0.5)
    assert rec["status"] == "failed"
    page.goto(f"{server.url}/#/logs")
    row = page.wait_for_selector(f"tr[data-log='{log_id}']")
    text = row.query_selector(".failure").text_content() or ""
    assert rec["job"]["error"]["detail"] in text and f"[{rec['job']['error']['code']}]" in text
    assert f"{round(100 * rec['progress'])} %" in text
    page.goto(f"{server.url}/#/analysis/{aid}")
    page.wait_for_selector("main .error")
    assert rec["job"]["error"]["detail"] in (page.text_content("main .error") or "")
    page.goto(f"{server.url}/#/analysis/an_0123456789abcdef")
    page.wait_for_selector("main .error")
    assert "an_0123456789abcdef" in (page.text_content("main .error") or "")


def _diagnosis_charts(page: Any, server: Server, did: str, report: dict[str, Any]) -> None:
    """The diagnosis charts show the API's numbers: residual by event and phase, before and after."""
    charts = api(server, f"/diagnoses/{did}/charts")
    assert [e["index"] for e in charts["events"]] == report["split"]["heldout"]
    bars = page.query_selector_all("#residual-by-phase rect.bar")
    groups = (("before", "before (baseline)"), ("after", f"after: + {charts['fitted']}"))
    expected = [(p["phase"], g, p[k]) for k, g in groups
                for p in charts["phases"] if p[k] is not None and p[k] > 0 and (k == "before" or charts["fitted"])]
    shown = [(b.get_attribute("data-category"), b.get_attribute("data-group"), float(b.get_attribute("data-value")))
             for b in bars]
    assert sorted(shown) == sorted(expected)
    assert len(page.query_selector_all("#residual-by-event rect.bar")) == sum(
        (e["before"] or 0) > 0 for e in charts["events"]) + sum((e["after"] or 0) > 0 for e in charts["events"])
    panels = page.query_selector_all("#diagnosis-overlays .panel")
    assert [int(p.get_attribute("data-event")) for p in panels] == [o["index"] for o in charts["overlays"]]
    scored = [c for c in report["candidates"] + report["pairs"] if c["heldout"].get("shrink")]
    assert len(page.query_selector_all("#shrink-chart g.interval")) == len(scored)
    for g in page.query_selector_all("#shrink-chart g.interval"):
        c = next(x for x in scored if x["title"] == g.get_attribute("data-label"))
        assert float(g.get_attribute("data-lo")) == pytest.approx(100 * c["heldout"]["shrink"]["lo"])
        assert float(g.get_attribute("data-hi")) == pytest.approx(100 * c["heldout"]["shrink"]["hi"])


def test_tolerance_band_and_gap_sensitivity_start_from_the_page(page: Any, server: Server, analysis_id: str) -> None:
    open_analysis(page, server, analysis_id)
    page.wait_for_selector("#tolerance-out >> text=not computed yet")
    page.wait_for_selector("#sensitivity-out >> text=not computed yet")
    page.click("#tolerance-start")
    page.click("#sensitivity-start")
    page.wait_for_selector("#tolerance-chart", timeout=600_000)
    page.wait_for_selector("#sensitivity-chart", timeout=600_000)
    assert page.get_attribute("#tolerance-out", "data-progress") is not None  # a progress bar was shown
    band = api(server, f"/analyses/{analysis_id}/tolerance?n=200")
    ok = [e for e in band["events"] if not e["error"]]
    items = page.query_selector_all("#tolerance-chart g.band-item")
    assert len(items) == len(ok)
    for g, e in zip(items, ok, strict=True):
        assert g.get_attribute("data-label") == f"#{e['index']}"
        assert float(g.get_attribute("data-measured")) == pytest.approx(e["measured_fluctuation_rpm"])
        inside = e["band_rpm"]["p5"] <= e["measured_fluctuation_rpm"] <= e["band_rpm"]["p95"]
        assert g.get_attribute("data-inside") == str(inside).lower()
    outside = sum(1 for e in ok if not e["band_rpm"]["p5"] <= e["measured_fluctuation_rpm"] <= e["band_rpm"]["p95"])
    assert f"{len(ok) - outside} of {len(ok)} events measured inside" in (page.text_content("#tolerance-summary") or "")
    rec = api(server, f"/analyses/{analysis_id}")
    sens = api(server, f"/vehicles/{rec['vehicle']}/gap-sensitivity?version={rec['vehicle_version']}")
    bars = page.query_selector_all("#sensitivity-chart rect.bar")
    shown = [float(b.get_attribute("data-value")) for b in bars]
    assert shown == pytest.approx([g["sensitivity"] for g in sens["gaps"]])
    assert f"per {sens['sensitivity_unit']}" in (page.text_content("#sensitivity-out") or "")
    screenshot(page, "tolerance-sensitivity", full_page=True)
    assert page.console_errors == [] and page.hosts <= {"127.0.0.1", "blob", "data"}
    # computed once: the next visit shows both without starting anything
    open_analysis(page, server, analysis_id)
    page.wait_for_selector("#tolerance-chart")
    page.wait_for_selector("#sensitivity-chart")
    assert page.query_selector("#tolerance-start") is None


# Last: this test leaves the server closed to requests without a key (its last key revoked).
def _keys(server: Server, *args: str) -> str:
    out = subprocess.run([sys.executable, "-m", "app", "keys", *args, "--data-dir", str(server.data_dir)],
                         capture_output=True, text=True, timeout=120, check=True)
    return out.stdout + out.stderr  # create: the key alone on stdout, then the notice on stderr


def test_the_api_key_goes_with_every_request(page: Any, server: Server) -> None:
    """A real key in the server's store: without it the API answers 401, with it the page works."""
    printed = _keys(server, "create", "--scope", "admin", "--name", "browser test")
    token = printed.splitlines()[0].strip()
    key_id = re.search(r"created key (\S+)", printed).group(1)  # type: ignore[union-attr]
    try:
        time.sleep(1.2)  # the server re-reads its keys within a second
        assert httpx.get(f"{server.url}/logs").status_code == 401
        seen: list[tuple[str, str | None]] = []
        page.on("request", lambda req: seen.append((req.url, req.headers.get("authorization"))))
        page.goto(f"{server.url}/#/logs")  # the page itself loads without a key
        page.fill("#api-key", token)
        page.click("#key-form button")
        page.wait_for_selector("#log-table, #no-logs")  # the list answered (it may be empty: tests run alone)
        api_calls = [(u, a) for u, a in seen if "/static/" not in u and urlparse(u).path not in ("/", "")]
        assert api_calls and all(a == f"Bearer {token}" for _, a in api_calls[-3:]), api_calls
        page.fill("#api-key", "")
        page.click("#key-form button")
    finally:
        _keys(server, "revoke", key_id)
        time.sleep(1.2)
    assert httpx.get(f"{server.url}/logs").status_code == 401  # the last key revoked: the server stays closed


def test_docs_work_offline(page: Any, server: Server) -> None:
    hosts: set[str] = set()
    page.on("request", lambda req: hosts.add(urlparse(req.url).hostname or ""))
    page.goto(f"{server.url}/docs")
    page.wait_for_selector(".swagger-ui .opblock", timeout=60_000)
    assert len(page.query_selector_all(".swagger-ui .opblock")) >= 30
    assert hosts == {"127.0.0.1"}
    assert httpx.get(f"{server.url}/redoc", follow_redirects=False).headers["location"] == "/docs"
