"""The Identify page and the diagnosis' "vehicle file off" card in a real Chromium against a real server.

Two 30 s drives of a car 25 % softer and 15 % heavier than the paper preset says (the vehicle ``ev`` of
the server), written as BLF through the reference DBC: one fitted, one withheld. What the page shows
is checked against what the API answers, and the page makes no request beyond the server.
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import Any
from urllib.parse import urlparse

import httpx
import pytest

from tests.api.conftest import Server, upload
from tests.identify.drives import write_drive_log
from tests.web.conftest import screenshot

pytestmark = [pytest.mark.browser, pytest.mark.slow]

TRUTH = {"stiffness": 0.75, "mass": 1.15}


@pytest.fixture(scope="module")
def drives(server: Server, tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The two drives uploaded: {"fit": log id, "withheld": log id}."""
    root = tmp_path_factory.mktemp("web-identify")
    ids = {}
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        for role, seed in (("fit", 31), ("withheld", 32)):
            r = upload(c, write_drive_log(root / f"drive_{role}.blf", TRUTH, seed, duration_s=30.0))
            assert r.status_code in (200, 201), r.text
            ids[role] = r.json()["id"]
    return ids


def api(server: Server, path: str, method: str = "GET", **kw: Any) -> Any:
    r = httpx.request(method, f"{server.url}{path}", timeout=60.0, **kw)
    assert r.status_code < 300, r.text
    return r.json()


def wait(server: Server, path: str, timeout: float) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while True:
        doc: dict[str, Any] = api(server, path)
        if doc["status"] not in ("queued", "running") or time.monotonic() > deadline:
            return doc
        time.sleep(2.0)


def watch(page: Any) -> tuple[list[str], set[str]]:
    """Console errors and the hosts of every request the page makes, as they happen."""
    errors: list[str] = []
    hosts: set[str] = set()
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    page.on("request", lambda req: hosts.add(urlparse(req.url).hostname or ""))
    return errors, hosts


def ratio_of(cell: str) -> float:
    """"0.75 [0.75, 0.75]" -> 0.75"""
    return float(cell.split("[")[0])


def test_identify_page_finds_the_file_off_and_applies_it(page: Any, server: Server, drives: dict[str, str]) -> None:
    errors, hosts = watch(page)
    versions = len(api(server, "/vehicles/ev/versions"))
    page.goto(f"{server.url}/#/identify")
    page.wait_for_selector("#identify-form")
    assert page.get_attribute("nav a.active", "data-page") == "identify"
    assert len(page.query_selector_all("#identify-form input[name=param]:checked")) == 4  # all four by default
    page.select_option("#identify-vehicle", "ev")
    page.check(f"tr[data-log='{drives['fit']}'] input[value=fit]")
    page.check(f"tr[data-log='{drives['withheld']}'] input[value=withheld]")
    screenshot(page, "identify-form")
    page.click("#identify-start")
    page.wait_for_url(re.compile(r"#/identify/id_[0-9a-f]{16}$"))
    iid = page.url.rsplit("/", 1)[1]
    page.wait_for_selector("#identify-head .progress")  # queued or running: a progress bar, as a diagnosis shows
    page.wait_for_selector("main[data-state='ready']", timeout=600_000)
    doc = api(server, f"/identifications/{iid}")
    assert doc["status"] == "done", doc
    assert doc["log_ids"] == [drives["fit"]] and doc["validate_log_ids"] == [drives["withheld"]]
    res = doc["result"]

    # the table: every parameter, the two the drive changed off the file with their ratios
    rows = page.query_selector_all("#identify-params tbody tr")
    assert [r.get_attribute("data-param") for r in rows] == list(res["params"])
    for name, truth in TRUTH.items():
        row = page.query_selector(f"#identify-params tr[data-param={name}]")
        assert row.get_attribute("data-status") == "off-file"
        assert "off the file" in (row.text_content() or "")
        assert ratio_of(row.query_selector("td.ratio").text_content() or "") == pytest.approx(truth, abs=0.04)
        assert res["params"][name]["unit"] in (row.text_content() or "")
    assert page.get_attribute("#identify-params tr[data-param=damping]", "data-status") == "matches"
    # these 100 Hz drives cross the lash in under two samples: held at the file's value, the reason in the row
    assert page.get_attribute("#identify-params tr[data-param=lash]", "data-status") == "not-identified"
    assert "free traverse" in (page.text_content("#identify-params tr[data-param=lash]") or "")
    headline = page.text_content("#identify-headline") or ""
    assert re.search(r"torsional stiffness at the motor 0\.7\dx the file \[0\.7\d, 0\.7\d\]", headline), headline
    assert "vehicle mass 1.1" in headline
    # the chart: one row per parameter, the changed ones marked, the file's value drawn
    assert len(page.query_selector_all("#identify-chart g.row")) == len(res["params"])
    assert {g.get_attribute("data-param") for g in page.query_selector_all("#identify-chart g.off-file")} == set(TRUTH)
    assert page.query_selector("#identify-chart .file-line")
    # the model-free mode and the withheld drive, as the API says
    assert f"{res['modal']['freq_hz']:.2f} Hz" in (page.text_content("#identify-modal") or "")
    rigid = page.text_content("#identify-rigid") or ""
    assert f"{res['rigid_body']['inertia_kgm2']:.4g} kg m^2 at the motor per logged N m" in rigid
    # the paper car's drive: the file's contact law kept, with both laws' residuals shown
    form = res["contact_damping"]
    assert form["contact_damping"] == "limited" and form["changed"] is False
    contact = page.text_content("#identify-contact") or ""
    assert contact.startswith("limited, as the file")
    assert all(f"{law} {x:.2f}" in contact for law, x in form["residual_to_noise"].items())
    val = res["validation"]
    text = page.text_content("#identify-validation") or ""
    assert f"{val['nrmse_before']:.3f} -> {val['nrmse_after']:.3f}" in text and val["verdict_after"] in text
    screenshot(page, "identify-result", full_page=True)

    with page.expect_download() as dl:
        page.click("#identify-download")
    toml = Path(dl.value.path()).read_text()
    assert toml == httpx.get(f"{server.url}/identifications/{iid}/vehicle").text and "[provenance]" in toml

    page.click("#identify-apply")
    page.wait_for_selector("#identify-applied >> text=stored ev")
    assert len(api(server, "/vehicles/ev/versions")) == versions + 1
    assert f"stored ev v{versions + 1}" in (page.text_content("#identify-applied") or "")
    start = api(server, f"/identifications/{iid}")["vehicle_version"]
    href = f"#/vehicles/ev/{start}/{versions + 1}"
    assert page.get_attribute("#identify-applied a", "href") == href
    page.click("#identify-applied a")  # the vehicle's page with the two versions compared in engineering figures
    page.wait_for_selector("#compare-figures")
    assert page.input_value("#compare-a") == str(start) and page.input_value("#compare-b") == str(versions + 1)
    figures = api(server, f"/vehicles/ev/compare?a={start}&b={versions + 1}")["figures"]
    assert len(page.query_selector_all("#compare-figures tbody tr")) == len(figures)
    page.go_back()
    assert api(server, f"/identifications/{iid}")["applied"] == {"vehicle": "ev", "version": versions + 1}

    page.wait_for_selector(f"#identify-applied a[href='{href}']")  # the page reloaded says it was applied
    page.goto(f"{server.url}/#/identify")  # this browser remembers the identification it started
    page.wait_for_selector(f"#identify-recent a[href='#/identify/{iid}']")
    assert not errors, errors
    assert hosts == {"127.0.0.1"}, hosts


def test_a_failed_or_unknown_identification_says_so(page: Any, server: Server, tmp_path: Path) -> None:
    short = write_drive_log(tmp_path / "short.blf", TRUTH, 33, duration_s=6.0)
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        log_id = upload(c, short).json()["id"]
    iid = api(server, "/identifications", "POST", json={"log_ids": [log_id], "vehicle": "ev"})["id"]
    doc = wait(server, f"/identifications/{iid}", 300.0)
    assert doc["status"] == "failed"
    page.goto(f"{server.url}/#/identify/{iid}")
    page.wait_for_selector("main[data-state='ready']")
    err = page.text_content("#identify-error") or ""
    assert doc["job"]["error"]["code"] in err and doc["job"]["error"]["detail"] in err
    page.goto(f"{server.url}/#/identify/id_0123456789abcdef")
    page.wait_for_selector("#identify-unknown")
    assert "no identification id_0123456789abcdef" in (page.text_content("#identify-unknown") or "")


def test_diagnosis_shows_the_vehicle_file_off(page: Any, server: Server, drives: dict[str, str]) -> None:
    errors, hosts = watch(page)
    aid = api(server, "/analyses", "POST", json={"log_id": drives["fit"], "vehicle": "ev", "vehicle_version": 1})["id"]
    assert wait(server, f"/analyses/{aid}", 600.0)["status"] == "done"
    did = api(server, f"/analyses/{aid}/diagnoses", "POST", json={"candidates": ["backlash"]})["id"]
    doc = wait(server, f"/diagnoses/{did}", 900.0)
    assert doc["status"] == "done", doc
    decision = doc["report"]["decision"]
    assert decision["status"] == "base_parameters" and not decision["identify_first"]
    page.goto(f"{server.url}/#/diagnosis/{did}")
    page.wait_for_selector("main[data-state='ready']", timeout=120_000)
    assert page.text_content("#decision .badge.base_parameters") == "base_parameters"
    items = page.query_selector_all("#base-parameters li")
    assert [li.get_attribute("data-param") for li in items] == [p["name"] for p in decision["base_parameters"]]
    card = page.text_content("#base-parameters") or ""
    for p in decision["base_parameters"]:
        assert f"{p['label']} {p['ratio']:.2f}x the file [{p['lo']:.2f}, {p['hi']:.2f}]" in card
    assert {p["name"] for p in decision["base_parameters"]} == set(TRUTH)
    ident = doc["report"]["identification"]
    assert len(page.query_selector_all("#diagnosis-identification-params tbody tr")) == len(ident["params"])
    assert "stiffness" in (page.text_content("#diagnosis-identification") or "")
    assert not page.query_selector("#identify-first")
    screenshot(page, "diagnosis-base-parameters", full_page=True)
    versions = len(api(server, "/vehicles/ev/versions"))  # the identified values stored as a version from here too
    page.click("#apply")
    page.wait_for_selector("#actions-result >> text=stored ev")
    assert len(api(server, "/vehicles/ev/versions")) == versions + 1

    # a parameter on a prior bound: the page says to identify the vehicle first, and offers nothing to apply
    bound = {**doc, "report": {**doc["report"], "decision": {**decision, "identify_first": True}}}
    page.route(f"**/diagnoses/{did}", lambda route: route.fulfill(json=bound))
    page.reload()
    page.wait_for_selector("main[data-state='ready']")
    assert page.get_attribute("#identify-first a", "href") == "#/identify"
    assert "Identify the vehicle first" in (page.text_content("#identify-first") or "")
    assert not page.query_selector("#apply")

    # effects that would change the log alike on a right data sheet (decision.mimicked_by) are named with their share
    assert not page.query_selector("#mimicked-by")
    alike = {**doc, "report": {**doc["report"], "decision": {
        **decision, "mimicked_by": [{"effect": "housing_mount", "linear_share": 0.7592}]}}}
    page.unroute(f"**/diagnoses/{did}")
    page.route(f"**/diagnoses/{did}", lambda route: route.fulfill(json=alike))
    page.reload()
    page.wait_for_selector("#mimicked-by")
    note = page.text_content("#mimicked-by") or ""
    assert "housing mount (76 %)" in note and "rule that out before correcting the file" in note
    assert not errors, errors
    assert hosts == {"127.0.0.1"}, hosts
