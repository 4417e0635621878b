"""How the service serves the dashboard fast (in process): its files from memory under a content-hash
version (cached for a year there, revalidated elsewhere), gzip where accepted, ``Server-Timing`` on
every answer, a finished analysis' results opened before the first view asks, and the time zone
of a log's clock named at upload."""

from __future__ import annotations

import gzip
import json
import re
import time
from collections.abc import Iterator
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from app.payload import SERIES_COLUMNS
from app.web import STATIC, assets
from tests.api.conftest import analysed, upload
from tests.api.inprocess import TestClient, in_process

GZ = {"Accept-Encoding": "gzip"}
PLAIN = {"Accept-Encoding": "identity"}


@pytest.fixture(scope="module")
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[TestClient]:
    with in_process(tmp_path_factory.mktemp("serving")) as c:
        yield c


def raw(c: TestClient, path: str, headers: dict[str, str]) -> tuple[int, dict[str, str], bytes]:
    """Status, headers and the body as sent (not decoded: the test client would inflate gzip)."""
    with c.stream("GET", path, headers=headers) as r:
        return r.status_code, dict(r.headers), b"".join(r.iter_raw())


def test_the_page_names_versioned_files_that_are_cached_for_a_year(client: TestClient) -> None:
    page = client.get("/")
    assert page.headers["cache-control"] == "no-cache"
    v = assets.version()
    assert re.fullmatch(r"[0-9a-f]{12}", v)
    refs = re.findall(r'(?:src|href)="(/static/[^"]+)"', page.text)
    assert len(refs) >= 8 and all(r.startswith(f"/static/{v}/") for r in refs)
    # early.js is in the page itself, not a request before the first reads can leave
    assert "early.js" not in " ".join(refs) and "window.lashscopeFirstReads" in page.text
    status, head, body = raw(client, f"/static/{v}/js/analysis.js", PLAIN)
    assert status == 200 and head["cache-control"] == "public, max-age=31536000, immutable"
    assert body == (STATIC / "js/analysis.js").read_bytes()
    assert head["content-type"].startswith("text/javascript")
    # unversioned, or an old version's prefix (a page open across an upgrade): revalidated, current bytes
    for path in ("/static/js/analysis.js", "/static/0123456789ab/js/analysis.js"):
        status, head, body = raw(client, path, PLAIN)
        assert status == 200 and head["cache-control"] == "no-cache"
        assert body == (STATIC / "js/analysis.js").read_bytes()
    # the docs page loads Swagger UI from the same versioned files
    assert f"/static/{v}/vendor/swagger-ui/swagger-ui-bundle.js" in client.get("/docs").text


def test_files_are_gzipped_when_accepted_and_revalidated_by_etag(client: TestClient) -> None:
    path = f"/static/{assets.version()}/vendor/uplot/uPlot.iife.min.js"
    source = (STATIC / "vendor/uplot/uPlot.iife.min.js").read_bytes()
    status, head, body = raw(client, path, GZ)
    assert status == 200 and head["content-encoding"] == "gzip" and head["vary"] == "Accept-Encoding"
    assert gzip.decompress(body) == source and len(body) < 0.6 * len(source)
    status, plain, body = raw(client, path, PLAIN)
    assert "content-encoding" not in plain and body == source
    assert plain["etag"] != head["etag"]  # each encoding its own tag
    for tag, enc in ((head["etag"], GZ), (plain["etag"], PLAIN)):
        status, again, body = raw(client, path, {**enc, "If-None-Match": tag})
        assert status == 304 and body == b"" and again["etag"] == tag
    # a changed file would have another tag: a stale one gets the body
    assert raw(client, path, {**PLAIN, "If-None-Match": '"stale"'})[0] == 200
    # too small to be worth it: sent as is
    status, head, body = raw(client, "/static/vendor/swagger-ui/NOTICE", GZ)
    assert status == 200 and "content-encoding" not in head
    assert body == (STATIC / "vendor/swagger-ui/NOTICE").read_bytes()


def test_unknown_files_are_a_typed_404(client: TestClient) -> None:
    for path in ("/static/nope.js", f"/static/{assets.version()}/js/nope.js", "/static/../app/settings.py",
                 "/static/js/../../__init__.py"):
        r = client.get(path)
        assert r.status_code == 404, path
        assert r.json()["code"] == "not_found"


def test_api_answers_are_gzipped_when_accepted(client: TestClient) -> None:
    status, head, body = raw(client, "/openapi.json", GZ)
    assert status == 200 and head["content-encoding"] == "gzip"
    status, plain, text = raw(client, "/openapi.json", PLAIN)
    assert "content-encoding" not in plain
    assert json.loads(gzip.decompress(body)) == json.loads(text)
    assert len(body) < len(text) / 3
    # small answers go as they are (the header would cost what compression saves)
    status, head, body = raw(client, "/health", GZ)
    assert status == 200 and "content-encoding" not in head and len(body) < 1024


def test_every_answer_says_the_services_time(client: TestClient) -> None:
    for path in ("/", "/health", "/static/js/app.js", "/logs/nope"):
        r = client.get(path)
        m = re.fullmatch(r"app;dur=(\d+\.\d{2})", r.headers["server-timing"])
        assert m, (path, r.headers.get("server-timing"))
        assert 0.0 <= float(m.group(1)) < 60_000.0


def test_the_log_clock_zone_named_at_upload_gives_utc_start_times(tmp_path: Path, demo_log: Path) -> None:
    with in_process(tmp_path / "data") as c:
        bad = c.post("/logs", params={"tz": "Mars/Olympus"}, content=demo_log.read_bytes(),
                     headers={"Content-Type": "application/octet-stream"})
        assert bad.status_code == 400 and bad.json()["code"] == "bad_time_zone"
        assert c.get("/logs").json() == []  # nothing stored
        with demo_log.open("rb") as fh:  # the form field, as the dashboard's upload sends it
            r = c.post("/logs", data={"tz": "Europe/Berlin"}, files={"file": (demo_log.name, fh)})
        assert r.status_code == 201, r.text
        # the demo BLF records a local wall clock without a zone: 2024-06-10 is summer time in Berlin
        naive = datetime.fromisoformat("2024-06-10T06:13:20.002000")
        stored = datetime.fromisoformat(r.json()["start_time"])
        assert stored.utcoffset() == timedelta(0)
        assert naive.replace(tzinfo=UTC) - stored == timedelta(hours=2)  # CEST, UTC+2
    with in_process(tmp_path / "data2") as c:
        r = c.post("/logs", params={"tz": "-05:30"}, content=demo_log.read_bytes(),
                   headers={"Content-Type": "application/octet-stream"})
        assert r.status_code == 201, r.text
        assert r.json()["start_time"] == "2024-06-10T11:43:20.002000+00:00"
        # without a zone the start stays the log's own wall clock
        r = upload(c, demo_log)
        assert r.status_code == 200 and r.json()["duplicate"] is True  # the same bytes: stored once
    with in_process(tmp_path / "data3") as c:
        assert upload(c, demo_log).json()["start_time"] == "2024-06-10T06:13:20.002000"


def test_results_are_opened_when_the_analysis_finishes(tmp_path: Path, demo_log: Path) -> None:
    """The first view after an analysis finds the result document parsed and the whole-log block
    extremes built (the job runner's hook), instead of paying for them on its first read."""
    with in_process(tmp_path / "data") as c:
        _, aid = analysed(c, demo_log)
        store, results = c.app.state.store, c.app.state.results  # type: ignore[attr-defined]
        directory = store.get_analysis(aid).result_dir
        deadline = time.monotonic() + 60.0  # the hook runs in the runner thread once the worker has ended; it
        # opens the document first and builds the extremes after, so a loaded machine can see the one without the other
        while (((files := results.peek(directory)) is None or not files.built(("block_extremes", *SERIES_COLUMNS)))
               and time.monotonic() < deadline):
            time.sleep(0.1)
        assert files is not None
        assert files.built(("block_extremes", *SERIES_COLUMNS))
        # the whole-log view read from them keeps every column's extremes of the full series
        every = c.get(f"/analyses/{aid}/speed", params={"max_points": 0}).json()
        view = c.get(f"/analyses/{aid}/speed", params={"max_points": 400}).json()
        assert view["points"] <= 400 < view["source_points"] == every["points"]
        for col in SERIES_COLUMNS:
            full = [v for v in every[col] if v is not None]
            kept = [v for v in view[col] if v is not None]
            assert (min(kept), max(kept)) == (min(full), max(full)), col
        # so do the decoded channels' (the pedal's is read beside the speed), whole log and a window
        for name in files.doc["signals"]:
            assert files.built(("signal_extremes", name))
            for q in ({}, {"t0": 7.5, "t1": 31.0}):
                all_rows = c.get(f"/analyses/{aid}/signals/{name}", params={"max_points": 0, **q}).json()
                view = c.get(f"/analyses/{aid}/signals/{name}", params={"max_points": 60, **q}).json()
                assert view["points"] <= 60 < view["source_points"] == all_rows["points"], name
                assert view["t_s"][0] == all_rows["t_s"][0] and view["t_s"][-1] == all_rows["t_s"][-1]
                full = [v for v in all_rows[name] if v is not None]
                kept = [v for v in view[name] if v is not None]
                assert (min(kept), max(kept)) == (min(full), max(full)), (name, q)
