"""The fleet page in a real Chromium: the event store of a real server (five synthetic vehicles of a
fleet and a drive analysed through the API), the per-log points, the band, the flags, the filter by
tracking verdict, the links to the analyses."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import httpx
import pytest

from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.fleet.store import write_rows
from app.settings import default_dbc_dir
from tests.api.conftest import Server, wait_for
from tests.fleet.test_report import _vehicle_rows
from tests.web.conftest import screenshot

pytestmark = [pytest.mark.browser, pytest.mark.slow]
EV02 = "document.querySelector(\"section.fleet-vehicle[data-vehicle='ev-02']\")"


@pytest.fixture(scope="module")
def fleet(server: Server, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    with httpx.Client(base_url=server.url, timeout=30.0) as c:
        assert c.get("/fleet").json()["code"] == "no_event_store"
        root = server.data_dir / "events"
        specs = {"ev-01": (18.0, 250.0, 420.0), "ev-02": (18.5, 255.0, 430.0), "ev-03": (17.5, 245.0, 410.0),
                 "ev-04": (18.2, 250.0, 425.0), "ev-05": (30.0, 330.0, 600.0)}  # ev-05: a worn driveline
        for seed, (name, spec) in enumerate(specs.items()):
            rows = _vehicle_rows(name, *spec, seed=seed)
            for r in rows:  # ev-02's first log does not track
                r["log_tracking"] = "poor" if r["log_hash"] == "ev-02-0" else "good"
            for h in sorted({r["log_hash"] for r in rows}):
                write_rows(root, [r for r in rows if r["log_hash"] == h], source="batch", log_hash=h)
        drive = tmp_path_factory.mktemp("fleet-web") / "drive.blf"
        dbc = default_dbc_dir()
        build_demo_log(drive, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml",
                       Scenario(duration_s=20.0, seed=5))
        with drive.open("rb") as fh:
            log_id = c.post("/logs?tz=UTC", files={"file": (drive.name, fh)}).json()["id"]
        aid = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
        assert wait_for(c, aid)["status"] == "done"
        return {"aid": aid, "log_id": log_id, "report": c.get("/fleet").json()}


def test_fleet_page_shows_points_band_flags_and_links(page: Any, server: Server, fleet: dict[str, Any]) -> None:
    rep = fleet["report"]
    # the worn ev-05 is flagged, the four like it are not (the analysed drive is another driveline: its own call)
    assert "ev-05" in rep["flagged"] and not {"ev-01", "ev-02", "ev-03", "ev-04"} & set(rep["flagged"])
    page.goto(f"{server.url}/#/fleet")
    page.wait_for_selector("main[data-state='ready']")
    rows = page.query_selector_all("#fleet-table tbody tr")
    assert [r.get_attribute("data-vehicle") for r in rows] == [v["vehicle"] for v in rep["vehicles"]]
    flagged = page.query_selector_all("#fleet-table tr.flagged")
    assert [r.get_attribute("data-vehicle") for r in flagged] == rep["flagged"]
    for row in flagged:  # the report's own reasons
        flags = next(v for v in rep["vehicles"] if v["vehicle"] == row.get_attribute("data-vehicle"))["flags"]
        assert flags and all(f in (row.text_content() or "") for f in flags)
    # one point per log with a time, each with its interval, the band drawn from the report
    for v in rep["vehicles"]:
        timed = [p for p in v["per_log"] if p["time"]]
        card = page.query_selector(f"section.fleet-vehicle[data-vehicle='{v['vehicle']}']")
        assert int(card.get_attribute("data-points")) == len(timed)
        pts = card.query_selector_all("svg[id^='ripple-'] .point")
        shown = [float(p.get_attribute("data-value")) for p in pts]
        assert shown == pytest.approx([p["ripple_rpm"]["median"] for p in timed])
    band = page.query_selector("svg[id='lash-ev-01'] rect.band")
    assert float(band.get_attribute("data-lo")) == pytest.approx(rep["bands"]["total_lash_deg"]["lo"])
    assert len(page.query_selector_all("svg[id='lash-ev-05'] .point.flagged")) == 10
    assert page.query_selector_all("svg[id='lash-ev-01'] .point.flagged") == []
    # the poor log is left out by default and counted
    assert rep["poor_tracking"]["events"] == 2 and rep["poor_tracking"]["logs"] == 1
    assert "2 events of 1 logs track poorly: left out" in (page.text_content("#fleet-poor") or "")
    assert page.get_attribute("section.fleet-vehicle[data-vehicle='ev-02']", "data-points") == "9"
    screenshot(page, "fleet", full_page=True)
    assert page.console_errors == [] and page.hosts <= {"127.0.0.1", "blob", "data"}
    page.select_option("#fleet-filter", "poor")
    page.wait_for_function(f"{EV02}?.dataset.points == '1'")
    assert page.get_attribute("section.fleet-vehicle[data-vehicle='ev-01']", "data-points") == "0"
    page.select_option("#fleet-filter", "all")
    page.wait_for_function(f"{EV02}?.dataset.points == '10'")
    # the analysed drive's point links to its analysis
    real = next(v for v in rep["vehicles"] if not v["vehicle"].startswith("ev-0"))
    assert real["per_log"][0]["analyses"][0]["id"] == fleet["aid"]
    page.click(f"svg[id='ripple-{real['vehicle']}'] a")
    page.wait_for_selector("main[data-page='analysis'][data-state='ready']", timeout=120_000)
    assert page.url.endswith(f"#/analysis/{fleet['aid']}")


def test_fleet_page_without_a_store_says_so(page: Any, tmp_path: Path) -> None:
    srv = Server(tmp_path / "empty").start()
    try:
        page.goto(f"{srv.url}/#/fleet")
        page.wait_for_selector("main[data-state='ready']")
        assert "no events stored yet" in (page.text_content("#fleet-body .error") or "")
    finally:
        srv.stop()
