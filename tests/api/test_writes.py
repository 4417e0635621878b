"""Every route that writes a file writes it under the data directory, from validated names only,
and leaves no temporary file behind when it refuses the request.

The app runs in this process on a real store; a diagnosis is given a finished job and a report
directly (running one takes minutes and is covered in tests/diagnosis), so the apply route is
exercised on its own.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest

from app.jobkinds import DIAGNOSIS_SEP
from tests.api.inprocess import TestClient, in_process, stored_analysis
from tests.conftest import REPO

REPORT_DOC = {"decision": {"status": "explained", "top": ["torque_lag"]},
              "candidates": [{"id": "torque_lag", "fit": {"params": {"torque_lag": {"tau_s": 0.012}}}}],
              "pairs": []}


def leftovers(data: Path) -> list[str]:
    return sorted(p.name for p in (data / "tmp").iterdir())


def finished_diagnosis(client: TestClient) -> str:
    """A diagnosis of an analysis of vehicle ``ev`` whose job is done and whose report chose torque_lag."""
    store, analysis = stored_analysis(client, "0" * 64, "x.log")
    diagnosis_id = f"{analysis.id}{DIAGNOSIS_SEP}0001"
    job = store.create_job("diagnosis", f"{analysis.id}/diagnoses/{diagnosis_id}")
    store.start_job(job.id)
    store.finish_job(job.id)
    status = {"id": diagnosis_id, "analysis_id": analysis.id, "job_id": job.id, "vehicle": {"name": "ev", "version": 1}}
    store.artifacts.put("diagnosis", diagnosis_id, "status", status)
    store.artifacts.put("diagnosis", diagnosis_id, "report", REPORT_DOC)
    return diagnosis_id


@pytest.mark.parametrize("name", ["{outside}/evil", "../../evil", "ev\x00x", "EV", "a" * 65, "x.y", ""])
def test_apply_refuses_a_bad_name_before_writing(tmp_path: Path, name: str) -> None:
    outside = tmp_path / "outside"
    outside.mkdir()
    name = name.format(outside=outside)
    data = tmp_path / "data"
    with in_process(data) as client:
        did = finished_diagnosis(client)
        before = sorted(p.relative_to(data) for p in data.rglob("*") if not p.name.startswith("lashscope.sqlite"))
        r = client.post(f"/diagnoses/{did}/apply", json={"name": name})
        assert r.status_code == 400, r.text
        assert r.json()["code"] == "invalid_vehicle_name"
        after = sorted(p.relative_to(data) for p in data.rglob("*") if not p.name.startswith("lashscope.sqlite"))
    assert after == before
    assert list(outside.iterdir()) == [] and not list(tmp_path.glob("*augmented*"))
    assert not (tmp_path.parent / "evil-augmented.toml").exists()


def test_apply_stores_the_augmented_vehicle_and_keeps_no_copy(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with in_process(data) as client:
        did = finished_diagnosis(client)
        r = client.post(f"/diagnoses/{did}/apply", json={"name": "ev-lag"})
        assert r.status_code == 201, r.text
        assert r.json()["vehicle"] == "ev-lag" and r.json()["effects"]["torque_lag"]["tau_s"] == 0.012
        toml = client.get("/vehicles/ev-lag/versions/1/driveline").text
        assert "tau_s = 0.012" in toml
        store = client.app.state.store  # type: ignore[attr-defined]
        assert [p for p in ("status", "report", "charts", "validation", "plot_events", "plot_residual")
                if store.artifacts.has("diagnosis", did, p)] == ["status", "report"]  # nothing else was written
        assert store.artifacts.get("diagnosis", did, "status")["applied"]["vehicle"] == "ev-lag"
        assert leftovers(data) == []


def test_vehicle_upload_with_a_repeated_file_field_leaves_nothing(tmp_path: Path) -> None:
    data = tmp_path / "data"
    toml = (REPO / "sim" / "presets" / "single_reduction.toml").read_bytes()
    with in_process(data) as client:
        files = [("driveline", (f"d{i}.toml", toml, "application/toml")) for i in range(4)]
        r = client.post("/vehicles", data={"name": "ev"}, files=files)
        assert r.status_code == 400 and r.json()["code"] == "repeated_field", r.text
        assert "driveline" in r.json()["detail"]
        assert leftovers(data) == []
        assert client.get("/vehicles").json() == []


@pytest.mark.parametrize("name", ["../evil", "/tmp/evil", "ev\x00", "Ev"])
def test_vehicle_upload_refuses_a_bad_name_before_checking_files(tmp_path: Path, name: str) -> None:
    data = tmp_path / "data"
    with in_process(data) as client:
        r = client.post("/vehicles", data={"name": name, "preset": "paper"})
        assert r.status_code == 400 and r.json()["code"] == "invalid_vehicle_name", r.text
        assert leftovers(data) == []
        assert sorted(p.name for p in (data / "vehicles").iterdir()) == []


def test_a_log_upload_with_a_second_file_is_refused_as_it_arrives(tmp_path: Path) -> None:
    data = tmp_path / "data"
    log = b"(0.000000) can0 123#00\n" * 1000
    with in_process(data) as client:
        for files, code in (([("file", ("a.log", log)), ("file", ("b.log", log))], "repeated_field"),
                            ([("file", ("a.log", log)), ("other", ("b.log", log))], "too_many_files")):
            r = client.post("/logs", files=files)
            assert r.status_code == 400 and r.json()["code"] == code, r.text
            assert leftovers(data) == []
        assert client.get("/logs").json() == []


def test_the_server_keeps_every_temporary_file_in_the_data_directory(tmp_path: Path) -> None:
    data = tmp_path / "data"
    before = tempfile.gettempdir()
    with in_process(data):
        assert Path(tempfile.gettempdir()) == (data / "tmp").resolve()  # inflated MF4s, libraries' files
    assert tempfile.gettempdir() == before
