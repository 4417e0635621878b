"""The identifications routes: start, poll, read the result, the identified file, apply as a vehicle version.

The app runs in the test process; the identification runs in the worker process it spawns, on two
uploaded BLF logs of a car 15 % heavier and 25 % softer than the paper preset says, written through
the reference DBC.
"""

from __future__ import annotations

import tomllib
import warnings
from collections.abc import Iterator
from pathlib import Path

import pytest

with warnings.catch_warnings():
    warnings.filterwarnings("ignore", message=".*httpx.*")
    from fastapi.testclient import TestClient

from app.api.main import create_app
from app.settings import Settings
from tests.api.conftest import create_vehicle, upload
from tests.diagnosis.test_api import wait
from tests.identify.drives import write_drive_log

TRUTH = {"stiffness": 0.75, "mass": 1.15}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("logs")
    return {name: write_drive_log(root / f"{name}.blf", TRUTH, seed, duration_s=30.0)
            for name, seed in (("drive_a", 31), ("drive_b", 32))}


@pytest.fixture()
def client(tmp_path: Path, logs: dict[str, Path]) -> Iterator[TestClient]:
    app = create_app(Settings(data_dir=tmp_path / "data", allowed_hosts=["testserver"]))
    with TestClient(app) as c:
        create_vehicle(c, "paper")
        ids = {}
        for name, path in logs.items():
            r = upload(c, path)
            assert r.status_code in (200, 201), r.text
            ids[name] = r.json()["id"]
        c.app_state = ids  # type: ignore[attr-defined]
        yield c


def test_identification_lifecycle(client: TestClient) -> None:
    ids = client.app_state  # type: ignore[attr-defined]
    r = client.post("/identifications", json={"log_ids": [ids["drive_a"]], "vehicle": "paper",
                                              "validate_log_ids": [ids["drive_b"]]})
    assert r.status_code == 202, r.text
    iid = r.json()["id"]
    doc = wait(client, f"/identifications/{iid}", timeout=300.0)
    assert doc["status"] == "done", doc
    res = doc["result"]
    assert sorted(res["named"]) == ["mass", "stiffness"]
    st, mass = res["params"]["stiffness"], res["params"]["mass"]
    assert st["value"] / st["nominal"] == pytest.approx(0.75, rel=0.04)
    assert mass["value"] == pytest.approx(1.15 * 1750.0, rel=0.03) and mass["lo"] < mass["value"] < mass["hi"]
    assert res["logs"][0]["name"] == "drive_a.blf"  # the upload's name, not the stored file's
    val = res["validation"]
    assert val["after"][0]["log"] == "drive_b.blf"
    assert val["nrmse_after"] < val["nrmse_before"]
    text = client.get(f"/identifications/{iid}/vehicle").text
    prov = tomllib.loads(text)["provenance"]
    assert prov["identified_from"] == "paper" and prov["logs"][0]["name"] == "drive_a.blf"
    assert prov["fitted"]["stiffness"]["ratio"] == pytest.approx(0.75, rel=0.04)
    applied = client.post(f"/identifications/{iid}/apply")
    assert applied.status_code == 201, applied.text
    assert applied.json()["version"] == 2
    versions = client.get("/vehicles/paper/versions").json()
    assert [v["version"] for v in versions] == [1, 2]
    assert client.get(f"/identifications/{iid}").json()["applied"] == {"vehicle": "paper", "version": 2}
    assert client.delete(f"/identifications/{iid}").status_code == 204
    assert client.get(f"/identifications/{iid}").status_code == 404


def test_bad_requests_are_refused_before_a_job(client: TestClient) -> None:
    ids = client.app_state  # type: ignore[attr-defined]
    same = client.post("/identifications", json={"log_ids": [ids["drive_a"]], "vehicle": "paper",
                                                 "validate_log_ids": [ids["drive_a"]]})
    assert same.status_code == 400 and "withheld drive must not be fitted" in same.json()["detail"]
    params = client.post("/identifications", json={"log_ids": [ids["drive_a"]], "vehicle": "paper",
                                                   "params": ["colour"]})
    assert params.status_code == 400 and "stiffness" in params.json()["detail"]
    missing = client.post("/identifications", json={"log_ids": ["lg_nope"], "vehicle": "paper"})
    assert missing.status_code == 404
    assert client.get("/identifications/id_0123456789abcdef").status_code == 404
    assert client.get("/identifications/../../etc").status_code == 404
    assert client.post("/identifications/id_0123456789abcdef/apply").status_code == 404


def test_too_few_events_fail_with_their_code(client: TestClient, tmp_path: Path) -> None:
    short = write_drive_log(tmp_path / "short.blf", TRUTH, 33, duration_s=6.0)
    log_id = upload(client, short).json()["id"]
    r = client.post("/identifications", json={"log_ids": [log_id], "vehicle": "paper"})
    doc = wait(client, f"/identifications/{r.json()['id']}", timeout=120.0)
    assert doc["status"] == "failed"
    assert doc["job"]["error"]["code"] == "insufficient_data"
    conflict = client.post(f"/identifications/{r.json()['id']}/apply")
    assert conflict.status_code == 409
