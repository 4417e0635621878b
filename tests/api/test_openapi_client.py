"""A client generated from the service's /openapi.json (openapi-python-client, a dev dependency) gets
typed fields: metrics per event with their units, events, the diagnosis report and the fleet rows are
classes with attributes, and each operation's own error set parses a 404 as ErrorOut with its code."""

from __future__ import annotations

import importlib
import json
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.api.conftest import Server, analysed

pytest.importorskip("openapi_python_client", reason="openapi-python-client is not installed (pip install -e '.[dev]')")


@pytest.fixture(scope="module")
def served(tmp_path_factory: pytest.TempPathFactory, demo_log: Path) -> Iterator[dict[str, Any]]:
    srv = Server(tmp_path_factory.mktemp("client") / "data").start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            log_id, aid = analysed(c, demo_log)
            spec = c.get("/openapi.json").json()
        yield {"server": srv, "log_id": log_id, "aid": aid, "spec": spec}
    finally:
        srv.stop()


@pytest.fixture(scope="module")
def client_pkg(served: dict[str, Any], tmp_path_factory: pytest.TempPathFactory) -> Any:
    root = tmp_path_factory.mktemp("generated")
    spec = root / "openapi.json"
    spec.write_text(json.dumps(served["spec"]), encoding="utf-8")
    out = subprocess.run([sys.executable, "-m", "openapi_python_client", "generate", "--path", str(spec), "--meta",
                          "none", "--output-path", str(root / "lashscope_client")],
                         capture_output=True, text=True, timeout=300, cwd=root)
    assert (root / "lashscope_client" / "client.py").is_file(), out.stdout + out.stderr
    sys.path.insert(0, str(root))
    try:
        yield importlib.import_module("lashscope_client")
    finally:
        sys.path.remove(str(root))


def _op(pkg: Any, tag: str, name: str) -> Any:
    return importlib.import_module(f"{pkg.__name__}.api.{tag}.{name}")


def test_generated_client_reads_typed_metrics_and_events(served: dict[str, Any], client_pkg: Any) -> None:
    with client_pkg.Client(base_url=served["server"].url, timeout=httpx.Timeout(60.0)) as c:
        _metrics_and_events(served, client_pkg, c)


def _metrics_and_events(served: dict[str, Any], client_pkg: Any, c: Any) -> None:
    aid = served["aid"]
    raw = httpx.get(f"{served['server'].url}/analyses/{aid}/metrics", timeout=60).json()
    m = _op(client_pkg, "analyses", "get_metrics_analyses_analysis_id_metrics_get").sync(client=c, analysis_id=aid)
    models = importlib.import_module(f"{client_pkg.__name__}.models")
    assert isinstance(m, models.MetricsOut)
    first = m.events[0]
    assert isinstance(first, models.EventMetricsOut)
    assert isinstance(first.measured.fluctuation_rpm, float)  # a field, not a dict key
    assert first.measured.fluctuation_rpm == raw["events"][0]["measured"]["fluctuation_rpm"]
    assert first.difference.gap_open_time_s == raw["events"][0]["difference"]["gap_open_time_s"]
    assert first.tracking.verdict == raw["events"][0]["tracking"]["verdict"]
    assert m.units["fluctuation_rpm"] == "rpm" and m.units["shuffle_freq_hz"] == "Hz"
    assert m.summary.with_metrics == len(m.events) and isinstance(m.summary.offset_ms, float)
    ev = _op(client_pkg, "analyses", "get_events_analyses_analysis_id_events_get").sync(client=c, analysis_id=aid)
    assert isinstance(ev.events[0], models.EventOut) and ev.count == len(ev.events)
    assert isinstance(ev.events[0].t_cross_s, float) and ev.events[0].kind in ("tip_in", "tip_out")
    # the unit is in the schema of every metric field
    props = served["spec"]["components"]["schemas"]["MetricValues"]["properties"]
    assert props["fluctuation_rpm"]["unit"] == "rpm" and props["settling_time_s"]["unit"] == "s"
    # an unknown id: the operation's 404 parses as the service's error, with its stable code
    r = _op(client_pkg, "analyses", "get_metrics_analyses_analysis_id_metrics_get").sync_detailed(
        client=c, analysis_id="an_0123456789abcdef")
    assert r.status_code == 404 and isinstance(r.parsed, models.ErrorOut) and r.parsed.code == "not_found"


def test_generated_client_reads_the_fleet_and_a_diagnosis_report(served: dict[str, Any], client_pkg: Any) -> None:
    with client_pkg.Client(base_url=served["server"].url, timeout=httpx.Timeout(60.0)) as c:
        _fleet_and_diagnosis(served, client_pkg, c)


def _fleet_and_diagnosis(served: dict[str, Any], client_pkg: Any, c: Any) -> None:
    models = importlib.import_module(f"{client_pkg.__name__}.models")
    fleet = _op(client_pkg, "fleet", "fleet_fleet_get").sync(client=c)
    assert isinstance(fleet, models.FleetOut)
    (vehicle,) = fleet.vehicles
    assert isinstance(vehicle.ripple_rpm.median, float) and vehicle.per_log[0].log_id == served["log_id"]
    create = _op(client_pkg, "diagnoses", "create_diagnosis_analyses_analysis_id_diagnoses_post")
    body = models.DiagnosisCreate(candidates=["backlash"])
    started = create.sync(client=c, analysis_id=served["aid"], body=body)
    get = _op(client_pkg, "diagnoses", "get_diagnosis_diagnoses_diagnosis_id_get")
    deadline = time.monotonic() + 900
    while (d := get.sync(client=c, diagnosis_id=started.id)).status in ("queued", "running"):
        assert time.monotonic() < deadline
        time.sleep(1.0)
    assert d.status == "done", d
    rep = d.report
    assert isinstance(rep, models.DiagnosisReportOut) and rep.schema == "lashscope.diagnosis/1"
    assert isinstance(rep.decision, models.DecisionOut) and rep.decision.status
    assert isinstance(rep.decision.heldout_shrink.value, float)
    assert rep.split.heldout and all(isinstance(i, int) for i in rep.split.heldout)
    raw = httpx.get(f"{served['server'].url}/diagnoses/{started.id}", timeout=60).json()["report"]
    assert rep.decision.reason == raw["decision"]["reason"]
    assert [x.id for x in rep.candidates] == [x["id"] for x in raw["candidates"]]
    charts = _op(client_pkg, "diagnoses", "get_charts_diagnoses_diagnosis_id_charts_get").sync(
        client=c, diagnosis_id=started.id)
    assert [e.index for e in charts.events] == rep.split.heldout


def test_each_operation_lists_its_own_errors(served: dict[str, Any]) -> None:
    paths = served["spec"]["paths"]

    def errors(method: str, path: str) -> set[str]:
        return {k for k in paths[path][method]["responses"] if k[0] in "45"}

    assert errors("get", "/health") == {"401", "403", "429", "500"}
    assert {"404", "409", "406"} <= errors("get", "/analyses/{analysis_id}/metrics")
    assert {"413", "415", "408"} <= errors("post", "/logs") and "409" not in errors("post", "/logs")
    assert "503" in errors("post", "/live/sessions") and "503" not in errors("get", "/logs")
    assert "404" not in errors("get", "/logs") and "404" in errors("get", "/logs/{log_id}")
    # a route's own description stays (the tolerance band's 404 says it is not computed)
    assert "POST" in paths["/analyses/{analysis_id}/tolerance"]["get"]["responses"]["404"]["description"]
    for ops in paths.values():
        for op in ops.values():
            for status, resp in op["responses"].items():
                if status[0] in "45":
                    schema = resp["content"]["application/json"]["schema"]
                    assert schema == {"$ref": "#/components/schemas/ErrorOut"}, (status, op["operationId"])
