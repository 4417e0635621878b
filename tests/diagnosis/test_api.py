"""The diagnoses routes: start, poll, read the report, plots, apply as a vehicle version, validate.

The app runs in the test process; each diagnosis runs in the worker process it spawns, on two
uploaded BLF logs of drives with a known truth (a 15 ms torque lag) written through the reference DBC.
"""

from __future__ import annotations

import os
import time
import warnings
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

with warnings.catch_warnings():
    # starlette asks for a renamed httpx package; the client works the same with the installed one
    warnings.filterwarnings("ignore", message=".*httpx.*")
    from fastapi.testclient import TestClient

from app.api.main import create_app
from app.settings import Settings
from tests.api.conftest import create_vehicle, upload
from tests.conftest import REPO
from tests.diagnosis.lagdrive import write_lag_log


@pytest.fixture(scope="module")
def lag_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    if not (REPO / "dbc" / "lashscope_ev.dbc").is_file():
        pytest.skip("the reference DBC and signal map are not in dbc/")
    root = tmp_path_factory.mktemp("logs")
    return {name: write_lag_log(root / f"{name}.blf", seed) for name, seed in (("log_a", 21), ("log_b", 22))}


@pytest.fixture()
def client(tmp_path: Path, lag_logs: dict[str, Path]) -> Iterator[TestClient]:
    app = create_app(Settings(data_dir=tmp_path / "data", allowed_hosts=["testserver"]))  # the test client's Host
    with TestClient(app) as c:
        store = app.state.store
        create_vehicle(c, "paper")
        ids = {}
        for name, path in lag_logs.items():
            r = upload(c, path)
            assert r.status_code in (200, 201), r.text
            ids[name] = r.json()["id"]
        analysis = store.create_analysis(ids["log_a"], store.get_vehicle("paper"), {})
        c.app_state = {"analysis": analysis.id, "log_b": ids["log_b"]}  # type: ignore[attr-defined]
        yield c


def wait(c: TestClient, url: str, key: str = "status", timeout: float = 120.0) -> dict[str, Any]:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        doc: dict[str, Any] = c.get(url).json()
        node = doc if key == "status" else doc.get(key, {})
        if node.get("status") in ("done", "failed"):
            return doc
        time.sleep(0.3)
    raise AssertionError(f"{url} not finished in {timeout} s")


def test_diagnosis_lifecycle(client: TestClient) -> None:
    st = client.app_state  # type: ignore[attr-defined]
    r = client.post(f"/analyses/{st['analysis']}/diagnoses",
                    json={"candidates": ["torque_lag", "drag", "speed_sensor"], "seed": 3})
    assert r.status_code == 202, r.text
    did = r.json()["id"]
    doc = wait(client, f"/diagnoses/{did}")
    assert doc["status"] == "done", doc
    rep = doc["report"]
    assert rep["schema"] == "lashscope.diagnosis/1"
    assert rep["decision"]["status"] == "explained" and rep["decision"]["top"] == ["torque_lag"]
    assert rep["split"]["seed"] == 3
    assert rep["findings"] == []  # the log checks ran and found nothing wrong with the log
    assert rep["read"]["damaged"] is False and rep["read"]["frames_read"] > 1000  # the read report came along
    assert rep["decision"]["residual_rms_rpm_before"] > rep["decision"]["residual_rms_rpm_after"] > 0
    for name in ("events", "residual"):
        png = client.get(f"/diagnoses/{did}/plots/{name}")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"
    # the plots' numbers: every held-out event, before and after the chosen fit, on time from the crossing
    charts = client.get(f"/diagnoses/{did}/charts").json()
    assert charts["schema"] == "lashscope.diagnosis-charts/1" and charts["fitted"] == "torque_lag"
    assert [e["index"] for e in charts["events"]] == rep["split"]["heldout"]
    assert sum(e["after"] < e["before"] for e in charts["events"]) >= 0.7 * len(charts["events"])
    assert [p["phase"] for p in charts["phases"]] == ["pre_event", "gap_traverse", "impact", "oscillation", "steady"]
    assert sum(b["before"] for b in charts["bands"]) == pytest.approx(1.0, abs=0.01)
    first = charts["overlays"][0]
    assert len(first["t_s"]) == len(first["measured_rpm"]) == len(first["baseline_rpm"]) == len(first["fitted_rpm"])
    assert first["t_s"][0] < 0 < first["t_s"][-1]  # time from the torque zero crossing
    resid = [(m - b) ** 2 for m, b in zip(first["measured_rpm"], first["baseline_rpm"], strict=True)]
    fitted = [(m - f) ** 2 for m, f in zip(first["measured_rpm"], first["fitted_rpm"], strict=True)]
    assert sum(fitted) < sum(resid)

    applied = client.post(f"/diagnoses/{did}/apply", json={})
    assert applied.status_code == 201, applied.text
    body = applied.json()
    assert body["vehicle"] == "paper" and body["version"] == 2
    assert body["effects"]["torque_lag"]["tau_s"] > 0.005

    v = client.post(f"/diagnoses/{did}/validate", json={"log_id": st["log_b"]})
    assert v.status_code == 202, v.text
    doc = wait(client, f"/diagnoses/{did}", key="validation")
    val = doc["validation"]
    assert val["status"] == "done", val
    assert val["shrink"]["value"] > 0.7
    assert val["read"]["damaged"] is False and val["read"]["note"] is None


def test_bad_requests(client: TestClient) -> None:
    st = client.app_state  # type: ignore[attr-defined]
    r = client.post(f"/analyses/{st['analysis']}/diagnoses", json={"candidates": ["gremlins"]})
    assert r.status_code == 400 and "gremlins" in r.json()["detail"]
    assert client.post("/analyses/nope/diagnoses", json={}).status_code == 404
    r = client.get("/diagnoses/nope")
    assert r.status_code == 404 and r.json()["code"] == "diagnosis_not_found"
    r = client.get("/diagnoses/nope/charts")
    assert r.status_code == 404 and r.json()["code"] == "diagnosis_not_found"


def test_deleting_the_analysis_cancels_its_diagnosis(client: TestClient) -> None:
    from tests.api.conftest import assert_gone, worker_pids

    st = client.app_state  # type: ignore[attr-defined]
    store = client.app.state.store  # type: ignore[attr-defined]
    r = client.post(f"/analyses/{st['analysis']}/diagnoses", json={"seed": 1})  # the whole library: minutes
    assert r.status_code == 202, r.text
    did, job_id = r.json()["id"], r.json()["job_id"]
    deadline = time.monotonic() + 90
    while not (workers := worker_pids(os.getpid())) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert workers, "the diagnosis never got a worker"
    assert client.delete(f"/analyses/{st['analysis']}").status_code == 204
    job = store.get_job(job_id)
    assert job.status.value == "failed" and job.error_code == "cancelled"
    assert st["analysis"] in (job.error_detail or "")
    assert_gone(workers, "the deleted analysis' diagnosis worker still runs")
    assert client.get(f"/diagnoses/{did}").status_code == 404
    assert store.job_counts()["running"] == 0
