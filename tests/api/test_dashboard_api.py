"""What the dashboard relies on, on a real server: the page and its assets served locally, /docs
without a CDN, metrics and events as CSV equal to the JSON, ``format=csv`` refused where there is no
CSV, vehicle versions compared field by field, the effect list, a response model for every JSON
route, and every static file covered by the package data."""

from __future__ import annotations

import csv
import io
import math
import re
import tomllib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.web import STATIC
from tests.api.conftest import Server, create_vehicle, upload, wait_for
from tests.conftest import REPO


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory, demo_log: Path) -> Iterator[tuple[httpx.Client, str]]:
    srv = Server(tmp_path_factory.mktemp("dash-api") / "data", max_upload_mb=64.0).start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            create_vehicle(c, "ev")
            log_id = upload(c, demo_log).json()["id"]
            aid = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()["id"]
            assert wait_for(c, aid, timeout=300)["status"] == "done"
            yield c, aid
    finally:
        srv.stop()


def test_the_page_and_docs_load_only_local_assets(served: tuple[httpx.Client, str]) -> None:
    c, _ = served
    for page in ("/", "/docs"):
        r = c.get(page)
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        refs = re.findall(r'(?:src|href)=["\']([^"\']+)["\']', r.text)
        assert refs, page
        for ref in refs:
            if ref.startswith(("#", "data:")):
                continue
            assert ref.startswith("/"), f"{page} loads {ref} from elsewhere"
            assert c.get(ref).status_code == 200, ref
    assert "openapi.json" in c.get("/docs").text
    r = c.get("/redoc", follow_redirects=False)
    assert r.status_code == 307 and r.headers["location"] == "/docs"


def _num(cell: str) -> float:
    return math.nan if cell == "" else float(cell)


def test_metrics_csv_holds_the_json_values(served: tuple[httpx.Client, str]) -> None:
    c, aid = served
    doc = c.get(f"/analyses/{aid}/metrics").json()
    r = c.get(f"/analyses/{aid}/metrics", params={"format": "csv"})
    assert r.status_code == 200 and r.headers["content-type"].startswith("text/csv")
    rows = list(csv.DictReader(io.StringIO(r.text)))
    assert len(rows) == len(doc["events"]) >= 10
    for row, m in zip(rows, doc["events"], strict=True):
        assert int(row["event_index"]) == m["event_index"] and row["kind"] == m["kind"]
        for name, value in m["measured"].items():
            if f"{name}_measured" in row and isinstance(value, float | int):
                assert _num(row[f"{name}_measured"]) == pytest.approx(value, nan_ok=True)
        assert _num(row["fluctuation_rpm_difference"]) == pytest.approx(m["difference"]["fluctuation_rpm"],
                                                                       nan_ok=True)
        assert row["tracking"] == m["tracking"]["verdict"]


def test_events_csv_lists_every_event_with_its_exclusion(served: tuple[httpx.Client, str]) -> None:
    c, aid = served
    doc = c.get(f"/analyses/{aid}/events").json()
    rows = list(csv.DictReader(io.StringIO(c.get(f"/analyses/{aid}/events?format=csv").text)))
    assert len(rows) == doc["count"]
    assert [r["exclusion"] for r in rows] == [e["exclusion"] or "" for e in doc["events"]]
    assert any(r["exclusion"] for r in rows)  # the demo drive brakes in some events (brake_cycle=3)
    assert [float(r["t_cross_s"]) for r in rows] == pytest.approx([e["t_cross_s"] for e in doc["events"]])


@pytest.mark.parametrize("path", ["/logs", "/vehicles", "/analyses/{aid}", "/analyses/{aid}/signals", "/health"])
def test_format_csv_is_refused_where_there_is_no_csv(served: tuple[httpx.Client, str], path: str) -> None:
    c, aid = served
    url = path.format(aid=aid)
    r = c.get(url, params={"format": "csv"})
    assert r.status_code == 406
    assert r.json() == {"detail": f"{url} answers JSON only; format=csv is not available here",
                        "code": "format_not_available"}
    assert c.get(url, params={"format": "json"}).status_code == 200


def test_two_vehicle_versions_compared_field_by_field(served: tuple[httpx.Client, str]) -> None:
    c, _ = served
    r = c.post("/vehicles", data={"name": "cmp", "preset": "paper"})
    assert r.status_code == 201
    r = c.post("/vehicles", data={"name": "cmp", "preset": "single_reduction"})
    assert r.status_code == 201 and r.json()["version"] == 2
    doc = c.get("/vehicles/cmp/compare", params={"a": 1, "b": 2}).json()
    fields = {f["field"]: f for f in doc["fields"]}
    a = _flat(c.get("/vehicles/cmp/versions/1/driveline").text)
    b = _flat(c.get("/vehicles/cmp/versions/2/driveline").text)
    assert set(fields) == set(a) | set(b)
    mass = fields["body.mass"]
    assert (mass["a"], mass["b"]) == (a["body.mass"], b["body.mass"])
    assert mass["delta"] == pytest.approx(b["body.mass"] - a["body.mass"])
    assert mass["ratio"] == pytest.approx(b["body.mass"] / a["body.mass"])
    assert doc["changed"] == sum(1 for k in fields if a.get(k) != b.get(k)) > 0
    assert doc["files_changed"] == []  # both versions use the project's DBC and signal map
    figures = {f["key"]: f for f in doc["figures"]}  # what the fields mean for the car, both versions
    assert figures["mass"]["ratio"] == pytest.approx(b["body.mass"] / a["body.mass"])
    assert figures["freq"]["unit"] == "Hz" and figures["freq"]["a"] > 0 and figures["freq"]["b"] > 0
    assert doc["provenance"] == {"a": None, "b": None}
    same = c.get("/vehicles/cmp/compare", params={"a": 2, "b": 2}).json()
    assert same["changed"] == 0 and not any(f["changed"] for f in same["fields"])
    missing = c.get("/vehicles/cmp/compare", params={"a": 1, "b": 9})
    assert missing.status_code == 404 and missing.json()["code"] == "not_found"


def _flat(toml_text: str) -> dict[str, Any]:
    from app.vehicle_compare import flatten

    return flatten(tomllib.loads(toml_text))


def test_effects_are_the_simulators_candidates(served: tuple[httpx.Client, str]) -> None:
    from sim.effects import EFFECTS

    c, _ = served
    body = c.get("/effects").json()
    assert [e["id"] for e in body] == list(EFFECTS)
    assert [e["title"] for e in body] == [e.title for e in EFFECTS.values()]


NON_JSON = {("get", "/analyses/{analysis_id}/speed"), ("get", "/analyses/{analysis_id}/events/{event}/speed"),
            ("get", "/analyses/{analysis_id}/signals/{name}"), ("get", "/vehicles/{name}/versions/{version}/driveline"),
            ("get", "/identifications/{identification_id}/vehicle"),
            ("get", "/diagnoses/{diagnosis_id}/plots/{name}"), ("get", "/live/sessions/{session_id}/stream")}


def test_every_json_route_publishes_its_response_model(served: tuple[httpx.Client, str]) -> None:
    c, _ = served
    spec = c.get("/openapi.json").json()
    missing = []
    for path, ops in spec["paths"].items():
        for method, op in ops.items():
            ok = next((op["responses"][s] for s in ("200", "201", "202") if s in op["responses"]), None)
            if ok is None or (method, path) in NON_JSON:
                continue
            schema = ok.get("content", {}).get("application/json", {}).get("schema", {})
            if not schema or schema == {"type": "object"} or schema.get("additionalProperties") is True:
                missing.append(f"{method.upper()} {path}")
    assert missing == []


def test_every_static_file_is_package_data() -> None:
    globs = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["app"]
    root = STATIC.parent.parent  # the app package: package-data globs are relative to it
    files = {p for p in STATIC.rglob("*") if p.is_file()}
    included = {p for g in globs for p in root.glob(g) if p.is_file()}  # setuptools' glob: '*' stays in a folder
    assert len(files) >= 15
    assert sorted(map(str, files - included)) == []
    for licence in ("vendor/uplot/LICENSE", "vendor/swagger-ui/LICENSE"):
        assert "Permission is hereby granted" in (STATIC / licence).read_text() or \
            "Apache License" in (STATIC / licence).read_text()
