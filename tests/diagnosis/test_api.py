"""The diagnoses routes in-process: start, poll, read the report, plots, apply as a vehicle version, validate.

The log decode edge (``_decode``: stored log + DBC + signal map -> signals) belongs to the ingest
path and is tested there; here it returns synthetic drives with a known truth so the routes'
own behaviour is what is checked.
"""

from __future__ import annotations

import hashlib
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
from app.api.routes import diagnoses
from app.settings import Settings
from sim import dump_toml
from tests.conftest import REPO
from tests.diagnosis.conftest import drive_signals, paper

LAG = (("tau_s", 0.015), ("delay_s", 0.0))


@pytest.fixture()
def client(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[TestClient]:
    logs = {"log_a": 21, "log_b": 22}

    def fake_decode(store: Any, log_id: str, name: str, version: int) -> tuple[Any, Any]:
        from sim import load_vehicle

        veh = store.get_vehicle(name, version)
        return drive_signals("torque_lag", LAG, logs[store.get_log(log_id).filename]), load_vehicle(veh.driveline_path)

    monkeypatch.setattr(diagnoses, "_decode", fake_decode)
    app = create_app(Settings(data_dir=tmp_path / "data"))
    with TestClient(app) as c:
        store = app.state.store
        ids = {}
        for name in logs:
            tmp = store.temp_path(".blf")
            tmp.write_bytes(name.encode())
            rec, _ = store.add_log(tmp, sha256=hashlib.sha256(name.encode()).hexdigest(), filename=name, fmt="blf",
                                   frames=1, duration_s=30.0, start_time=None, issues=[], meta={})
            ids[name] = rec.id
        files = tmp_path / "files"
        files.mkdir()
        (files / "paper.toml").write_text(dump_toml(paper()), encoding="utf-8")
        dbc, smap = REPO / "dbc" / "lashscope_ev.dbc", REPO / "dbc" / "lashscope_ev.map.toml"
        if not (dbc.is_file() and smap.is_file()):
            pytest.skip("the reference DBC and signal map are not in dbc/")
        veh, _ = store.add_vehicle("paper", driveline=files / "paper.toml", database=dbc, signal_map=smap,
                                   summary={})
        analysis = store.create_analysis(ids["log_a"], veh, {})
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


def test_diagnosis_lifecycle(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
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
    for name in ("events", "residual"):
        png = client.get(f"/diagnoses/{did}/plots/{name}")
        assert png.status_code == 200 and png.content[:4] == b"\x89PNG"

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


def test_bad_requests(client: TestClient) -> None:
    st = client.app_state  # type: ignore[attr-defined]
    r = client.post(f"/analyses/{st['analysis']}/diagnoses", json={"candidates": ["gremlins"]})
    assert r.status_code == 400 and "gremlins" in r.json()["detail"]
    assert client.post("/analyses/nope/diagnoses", json={}).status_code == 404
    r = client.get("/diagnoses/nope")
    assert r.status_code == 404 and r.json()["code"] == "diagnosis_not_found"
