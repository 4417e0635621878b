"""The analysis payload carries the read report: a BLF cut short is stated with its frames and seconds lost."""

from __future__ import annotations

from pathlib import Path

from tests.api.conftest import create_vehicle, wait_for
from tests.api.inprocess import in_process


def test_truncated_log_is_stated_in_the_analysis(tmp_path: Path, demo_log: Path) -> None:
    cut = demo_log.read_bytes()[:100_000]
    with in_process(tmp_path / "data") as client:
        create_vehicle(client)
        log = client.post("/logs", files={"file": ("cut.blf", cut)}).json()
        assert log["issues"][0]["kind"] == "truncated"
        aid = client.post("/analyses", json={"log_id": log["id"], "vehicle": "ev"}).json()["id"]
        assert wait_for(client, aid, timeout=300)["status"] == "done"
        read = client.get(f"/analyses/{aid}").json()["summary"]["read"]
        assert client.get(f"/analyses/{aid}/metrics").json()["summary"]["read"] == read
    assert read["damaged"] and read["truncated"] and read["frames_read"] == log["frames"]
    assert read["frames_lost"] > 5000 and read["seconds_lost"] > 15  # the demo drive runs 40 s; 100 kB hold ~20 s
    assert read["note"].startswith("the log is truncated (truncated at byte offset ")


def test_intact_log_has_no_note(tmp_path: Path, demo_log: Path) -> None:
    with in_process(tmp_path / "data") as client:
        create_vehicle(client)
        log = client.post("/logs", files={"file": ("drive.blf", demo_log.read_bytes())}).json()
        aid = client.post("/analyses", json={"log_id": log["id"], "vehicle": "ev"}).json()["id"]
        assert wait_for(client, aid, timeout=300)["status"] == "done"
        read = client.get(f"/analyses/{aid}").json()["summary"]["read"]
    assert read["damaged"] is False and read["note"] is None and read["frames_lost"] is None
