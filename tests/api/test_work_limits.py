"""Small inputs cannot start unbounded work in the server: each attack gets 413/422 naming its limit,
decided before (or bounded during) the work, and leaves no temporary file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest

from app.ingest import database
from tests.api.attacks import BOMB_LINES, blf_bomb, gzip_bomb, many_stage_driveline, overlapping_dbc
from tests.api.inprocess import TestClient, in_process


@pytest.fixture
def client(tmp_path: Path) -> Iterator[TestClient]:
    with in_process(tmp_path / "data") as c:
        yield c
        assert list((tmp_path / "data" / "tmp").iterdir()) == []


def post_vehicle(client: TestClient, **files: bytes) -> dict[str, object]:
    r = client.post("/vehicles", data={"name": "ev"} if "driveline" in files else {"name": "ev", "preset": "paper"},
                    files={k: (f"{k}.bin", v, "application/octet-stream") for k, v in files.items()})
    body: dict[str, object] = {"status": r.status_code, **r.json()}
    return body


def test_a_driveline_of_many_stages_is_refused_before_any_check(client: TestClient) -> None:
    huge = many_stage_driveline(10_000)
    assert len(huge) > 1_000_000
    r = post_vehicle(client, driveline=huge)
    assert (r["status"], r["code"]) == (413, "vehicle_file_too_large")
    assert "256 KiB" in str(r["detail"])
    r = post_vehicle(client, driveline=many_stage_driveline(30))
    assert (r["status"], r["code"]) == (422, "invalid_parameter")
    assert "30 stages" in str(r["detail"]) and "at most 24 stages" in str(r["detail"])
    assert post_vehicle(client, driveline=many_stage_driveline(24))["status"] == 201


def test_a_dbc_crowding_one_message_is_refused_before_parsing(client: TestClient) -> None:
    r = post_vehicle(client, dbc=overlapping_dbc(1100))
    assert (r["status"], r["code"]) == (422, "database_too_complex")
    assert "1100 signals, more than the 1024" in str(r["detail"])
    r = post_vehicle(client, dbc=bytes(5 * 2**20))  # stopped while it arrives: past the largest file's cap
    assert (r["status"], r["code"]) == (413, "upload_too_large") and "4 MiB cap" in str(r["detail"])


def test_repairing_overlaps_stops_at_its_cpu_budget(client: TestClient, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(database, "REPAIR_CPU_S", 0.2)
    r = post_vehicle(client, dbc=overlapping_dbc(400, filler_messages=200))
    assert (r["status"], r["code"]) == (422, "database_too_complex")
    assert "0.2 s of CPU (the limit of repairing a DBC)" in str(r["detail"])
    assert "overlap in message Crowded" in str(r["detail"])


def test_a_few_overlaps_are_still_repaired(client: TestClient) -> None:
    r = post_vehicle(client, dbc=overlapping_dbc(3, filler_messages=2))
    assert r["status"] == 422 and r["code"] == "signal_map_error"  # loaded (two repairs); the map does not fit it


def test_gap_sensitivity_past_its_work_limit_is_refused_before_simulating(client: TestClient) -> None:
    assert post_vehicle(client, driveline=many_stage_driveline(24, stiffness=1e8))["status"] == 201
    r = client.get("/vehicles/ev/gap-sensitivity")
    assert r.status_code == 422 and r.json()["code"] == "work_limit"
    assert "more than the limit of 4e+08" in r.json()["detail"] and "24 stages" in r.json()["detail"]
    assert post_vehicle(client, driveline=many_stage_driveline(24))["status"] == 201  # soft stages: version 2
    doc = client.get("/vehicles/ev/gap-sensitivity").json()
    assert doc["version"] == 2 and len(doc["gaps"]) == 24


@pytest.mark.parametrize("fmt", ["candump", "asc", "trc", "mf4"])
def test_compression_bombs_get_413_naming_the_cap(tmp_path: Path, fmt: str) -> None:
    # the inflation cap, not the reading's CPU limit (test_validating_an_upload_stops_at_its_cpu_limit): on a slow or
    # loaded machine the candump bomb's 0.46 M lines took over the default 8 s to read before the cap was reached
    bomb = gzip_bomb(fmt, 40 * 2**20)
    with in_process(tmp_path / "data", validate_cpu_s=300.0) as client:
        r = client.post("/logs", params={"filename": f"drive.{fmt}.gz"}, content=bomb,
                        headers={"content-type": "application/octet-stream"})
        assert r.status_code == 413 and r.json()["code"] == "inflated_too_large", r.text
        assert "32 MiB cap for compressed logs (32x its compressed size)" in r.json()["detail"]
        assert client.get("/logs").json() == []


def test_validating_an_upload_stops_at_its_cpu_limit(tmp_path: Path) -> None:
    log = BOMB_LINES["candump"] * 400_000  # 18 MB of text: about 2 s to read
    with in_process(tmp_path / "data", validate_cpu_s=0.05) as client:
        r = client.post("/logs", params={"filename": "drive.log"}, content=log,
                        headers={"content-type": "application/octet-stream"})
        assert r.status_code == 422 and r.json()["code"] == "validation_limit", r.text
        assert r.json()["detail"].startswith("drive.log: reading it took more than 0.05 s of CPU "
                                             "(LASHSCOPE_VALIDATE_CPU_S)")
        assert client.get("/logs").json() == []
    assert list((tmp_path / "data" / "tmp").iterdir()) == []
    with in_process(tmp_path / "data") as client:  # the default limit reads it
        r = client.post("/logs", params={"filename": "drive.log"}, content=log,
                        headers={"content-type": "application/octet-stream"})
        assert r.status_code == 201 and r.json()["frames"] == 400_000, r.text


def test_a_log_of_damaged_lines_stops_at_the_cpu_limit_too(tmp_path: Path) -> None:
    # no line gives a frame, so no chunk is ever complete: the limit is checked as the log is read, not per chunk
    log = b";$FILEVERSION=1.1\n" + b"     1)         0.0  Rx         0123  8  00 11 22 ZZ 44 55 66 77\n" * 200_000
    with in_process(tmp_path / "data", validate_cpu_s=0.05) as client:
        r = client.post("/logs", params={"filename": "drive.trc"}, content=log,
                        headers={"content-type": "application/octet-stream"})
        assert r.status_code == 422 and r.json()["code"] == "validation_limit", r.text
        assert "0 frames were read by then" in r.json()["detail"]
        assert client.get("/logs").json() == []
    with in_process(tmp_path / "data") as client:  # read to the end: nothing in it is a frame
        r = client.post("/logs", params={"filename": "drive.trc"}, content=log,
                        headers={"content-type": "application/octet-stream"})
        assert r.status_code == 422 and "no frames could be read" in r.json()["detail"], r.text
        assert "data byte 4 'ZZ'" in r.json()["detail"] and "line 2" in r.json()["detail"]


def test_a_blf_of_compressible_containers_stops_at_the_ratio_cap(client: TestClient) -> None:
    bomb = blf_bomb(800_000)  # 38 MB of frame objects in about 140 kB
    r = client.post("/logs", params={"filename": "drive.blf"}, content=bomb,
                    headers={"content-type": "application/octet-stream"})
    assert r.status_code == 413 and r.json()["code"] == "inflated_too_large", r.text
    assert r.json()["detail"] == ("drive.blf: decompresses to more than the 32 MiB cap for compressed logs (32x its "
                                  "compressed size); decompress it yourself or raise the cap")


def test_gap_sensitivity_started_in_the_background_reports_progress(client: TestClient) -> None:
    import time

    assert post_vehicle(client, driveline=many_stage_driveline(24, stiffness=1e8))["status"] == 201
    r = client.post("/vehicles/ev/gap-sensitivity")  # refused now, not in the background
    assert r.status_code == 422 and r.json()["code"] == "work_limit"
    assert post_vehicle(client)["status"] == 201  # the paper preset: version 2
    r = client.get("/vehicles/ev/gap-sensitivity", params={"compute": False})  # a read that never starts work
    assert r.status_code == 404 and r.json()["code"] == "gap_sensitivity_not_started"
    assert client.get("/vehicles/ev/gap-sensitivity/status").json() == {
        "status": "not_started", "progress": 0.0, "stage": "", "job_id": None, "error": None,
        "elapsed_s": None, "eta_s": None}
    r = client.post("/vehicles/ev/gap-sensitivity")
    assert r.status_code == 202, r.text
    job = r.json()
    assert job["version"] == 2 and job["status"] in ("queued", "running", "done")
    seen = []
    deadline = time.monotonic() + 300
    while (r := client.get("/vehicles/ev/gap-sensitivity", params={"compute": False})).status_code == 202:
        seen.append(r.json()["progress"])
        assert r.json()["job_id"] == job["job_id"] and time.monotonic() < deadline
        time.sleep(0.2)
    assert r.status_code == 200 and seen == sorted(seen) and all(0 <= p <= 1 for p in seen)
    doc = r.json()
    assert doc["version"] == 2 and len(doc["gaps"]) == 5 and doc["sensitivity_unit"] in ("mm", "rad")
    assert client.get("/vehicles/ev/gap-sensitivity/status", params={"version": 2}).json()["status"] == "done"
    assert client.get("/vehicles/ev/gap-sensitivity/status", params={"version": 1}).json()["status"] == "not_started"
    again = client.post("/vehicles/ev/gap-sensitivity")  # computed: the document at once
    assert again.status_code == 200 and again.json() == doc
