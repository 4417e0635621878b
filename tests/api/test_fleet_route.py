"""``GET /fleet`` on a real server: the service's analyses write the event store the fleet report reads."""

from __future__ import annotations

from pathlib import Path

import httpx

from app.fleet.store import read_events
from tests.api.conftest import Server, create_vehicle, upload, wait_for


def test_analysis_rows_reach_the_fleet_report(server: Server, demo_log: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=30.0) as client:
        r = client.get("/fleet")
        assert r.status_code == 404 and r.json()["code"] == "no_event_store"
        assert str(server.data_dir) not in r.text
        create_vehicle(client)
        log_id = upload(client, demo_log).json()["id"]
        analysis = client.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()
        assert wait_for(client, analysis["id"])["status"] == "done"
        events = client.get(f"/analyses/{analysis['id']}/events").json()["events"]
        r = client.get("/fleet", params={"band_k": 2.5})
        assert r.status_code == 200, r.text
        report = r.json()
        assert client.get("/fleet", params={"band_k": 0}).status_code == 422
        kept = client.get("/fleet", params={"include_poor_tracking": True}).json()
    frame = read_events(server.data_dir / "events")
    assert len(frame) == len(events) and set(frame["source"]) == {"service"}
    (vehicle,) = report["vehicles"]
    assert vehicle["logs"] == 1 and report["band_k"] == 2.5 and report["bands"]["ripple_rpm"] is None
    assert report["poor_tracking"] == {"events": 0, "logs": 0, "included": False}  # the demo drive tracks
    assert kept["poor_tracking"]["included"] is True and kept["vehicles"] == report["vehicles"]
    with_metrics = frame[frame["measured_fluctuation_rpm"].notna()]
    assert vehicle["events"] == len(with_metrics) >= 4
    assert vehicle["ripple_rpm"]["median"] == with_metrics["measured_fluctuation_rpm"].median()
    # each log's point links to the stored log and its analyses
    (point,) = vehicle["per_log"]
    assert point["log_id"] == log_id and point["analyses"][0]["id"] == analysis["id"]
    assert point["events"] == vehicle["events"] and point["ripple_rpm"]["median"] == vehicle["ripple_rpm"]["median"]
