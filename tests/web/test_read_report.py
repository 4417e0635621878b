"""A damaged log in the dashboard: the analysis view says so, with the frames and seconds lost; the upload
card lists the formats the service reads (from app/log_formats.py) and takes a format description."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.log_formats import LOG_FORMATS
from app.settings import default_dbc_dir
from tests.api.conftest import Server, wait_for

pytestmark = [pytest.mark.browser, pytest.mark.slow]


@pytest.fixture(scope="module")
def cut_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 40 s demo drive as BLF, cut at 100 kB as a full disk or an interrupted copy leaves it."""
    folder = tmp_path_factory.mktemp("cut")
    whole = folder / "drive.blf"
    dbc = default_dbc_dir()
    build_demo_log(whole, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml", Scenario(duration_s=40.0))
    cut = folder / "cut.blf"
    cut.write_bytes(whole.read_bytes()[:100_000])
    return cut


def test_analysis_view_states_the_truncation(page: Any, server: Server, cut_log: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        log = c.post("/logs", files={"file": (cut_log.name, cut_log.read_bytes())}).json()
        aid = c.post("/analyses", json={"log_id": log["id"], "vehicle": "ev"}).json()["id"]
        assert wait_for(c, aid, timeout=300)["status"] == "done"
        read = c.get(f"/analyses/{aid}").json()["summary"]["read"]
    assert read["truncated"] and read["frames_lost"] > 5000 and 15 < read["seconds_lost"] < 25
    page.goto(f"{server.url}/#/analysis/{aid}")
    page.wait_for_selector("main[data-state='ready']", timeout=120_000)
    note = page.text_content("#read-report") or ""
    assert note.startswith("truncated log: the log is truncated")
    assert f"{read['frames_lost']} frame(s) ({read['seconds_lost']:.1f} s) lost" in note


def test_upload_card_lists_the_formats_of_the_registry(page: Any, server: Server) -> None:
    page.goto(f"{server.url}/#/logs")
    page.wait_for_function("document.querySelector('#log-formats')?.textContent.includes('gzip accepted')")
    text = page.text_content("#log-formats") or ""
    for f in LOG_FORMATS:
        assert f.label in text
    assert page.get_attribute("#upload-format", "accept") == ".toml"
    assert re.search(r"or a text format described in a TOML file; gzip accepted", text)
