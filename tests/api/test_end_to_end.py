"""Through real HTTP against uvicorn on loopback: upload, analyse, read events, metrics and speed."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import httpx
import pytest

from tests.api.conftest import Server, create_vehicle, upload, wait_for


def test_upload_analyse_and_read_everything(server: Server, demo_log: Path) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        vehicle = create_vehicle(c)
        assert vehicle["version"] == 1 and vehicle["summary"]["vehicle"] == "paper"
        again = c.post("/vehicles", data={"name": "ev", "preset": "paper"})
        assert again.status_code == 200 and again.json()["unchanged"] is True

        r = upload(c, demo_log)
        assert r.status_code == 201, r.text
        log = r.json()
        assert log["format"] == "blf" and log["frames"] > 10000 and 35 < log["duration_s"] < 41
        dup = upload(c, demo_log)
        assert dup.status_code == 200 and dup.json()["duplicate"] is True and dup.json()["id"] == log["id"]
        assert [x["id"] for x in c.get("/logs").json()] == [log["id"]]

        r = c.post("/analyses", json={"log_id": log["id"], "vehicle": "ev"})
        assert r.status_code == 202, r.text
        analysis_id = r.json()["id"]
        done = wait_for(c, analysis_id)
        assert done["status"] == "done", done
        assert done["progress"] == 1.0

        events = c.get(f"/analyses/{analysis_id}/events").json()["events"]
        assert len(events) >= 10
        kinds = {e["kind"] for e in events}
        assert kinds == {"tip_in", "tip_out"}
        assert any(e["exclusion"] and e["exclusion"].startswith("braking") for e in events)
        analysed = [e for e in events if e["has_metrics"]]
        assert len(analysed) >= 6

        metrics = c.get(f"/analyses/{analysis_id}/metrics").json()
        # the demo truth has 20 % less half-shaft gap than the preset: the simulated ripple is larger
        summ = metrics["summary"]["metrics"]["fluctuation_rpm"]
        assert summ["measured_median"] > 50 and summ["difference_median"] > 0
        assert 0.004 < metrics["offset"]["lag_s"] < 0.012  # the scenario delays the speed by 8 ms
        for m in metrics["events"]:
            assert m["measured"]["shuffle_freq_hz"] is None or 5 < m["measured"]["shuffle_freq_hz"] < 11
            assert m["rms_rpm"] is not None and m["nrmse"] is not None
            assert m["tracking"] == {"verdict": "good", "reasons": []}
            assert m["measured"]["resolution"] == {}  # 10 ms messages resolve every metric
        # the demo's simulation tracks: the verdict says so, the offset is applied
        assert metrics["tracking"] == metrics["summary"]["tracking"] == {"verdict": "good", "reasons": []}
        assert metrics["summary"]["offset_applied"] is True and metrics["offset"]["applied"] is True
        assert metrics["sampling"]["motor_speed_rpm"]["mean_ms"] == pytest.approx(10.0, rel=0.05)
        assert metrics["sampling"]["motor_speed_rpm"]["bursty"] is False
        assert c.get(f"/analyses/{analysis_id}").json()["summary"]["tracking"]["verdict"] == "good"
        assert all(e["tracking"] is None for e in events if not e["has_metrics"])

        full = c.get(f"/analyses/{analysis_id}/speed", params={"max_points": 0}).json()
        small = c.get(f"/analyses/{analysis_id}/speed", params={"max_points": 2000}).json()
        assert small["points"] <= 2000 < full["points"] == small["source_points"]
        for col in ("measured_rpm", "simulated_rpm"):
            assert max(v for v in small[col] if v is not None) == max(v for v in full[col] if v is not None)
            assert min(v for v in small[col] if v is not None) == min(v for v in full[col] if v is not None)
        lttb = c.get(f"/analyses/{analysis_id}/speed", params={"max_points": 1000, "method": "lttb"}).json()
        assert lttb["points"] == 1000 and lttb["t_s"][0] == full["t_s"][0] and lttb["t_s"][-1] == full["t_s"][-1]
        assert set(lttb["t_s"]) <= set(full["t_s"])
        bad = c.get(f"/analyses/{analysis_id}/speed", params={"method": "every-third"})
        assert bad.status_code == 422 and bad.json()["code"] == "validation_error"

        k = analysed[0]["index"]
        ev = c.get(f"/analyses/{analysis_id}/events/{k}/speed", params={"format": "csv", "max_points": 500})
        assert ev.headers["content-type"].startswith("text/csv")
        rows = list(csv.reader(io.StringIO(ev.text)))
        assert rows[0] == ["t_s", "measured_rpm", "simulated_rpm", "torque_nm"] and 10 < len(rows) <= 501
        window = c.get(f"/analyses/{analysis_id}/speed", params={"t0": 10.0, "t1": 12.0, "max_points": 0}).json()
        assert window["t_s"][0] >= 10.0 and window["t_s"][-1] <= 12.0

        sigs = c.get(f"/analyses/{analysis_id}/signals").json()["signals"]
        assert {"motor_torque_nm", "motor_speed_rpm", "pedal_pct"} <= set(sigs)
        torque = c.get(f"/analyses/{analysis_id}/signals/motor_torque_nm", params={"max_points": 100}).json()
        assert torque["points"] <= 100 and torque["columns"] == ["motor_torque_nm"]

        sens = c.get("/vehicles/ev/gap-sensitivity").json()
        assert [g["gap"] for g in sens["gaps"]][-1] == "halfshaft"
        assert sens["gaps"][-1]["sensitivity"] == pytest.approx(100.0)
        assert sens["sensitivity_unit"] == "mm"  # the paper preset gives every contact radius
        assert all(g["sensitivity"] == g["sensitivity_per_mm"] and g["sensitivity_per_rad"] > 0 for g in sens["gaps"])
        assert all(g["sensitivity"] < 100.0 for g in sens["gaps"][:3])
        assert sens["zero_gaps"]["impact_rpm"] == 0.0

        cors = c.get("/health", headers={"Origin": "http://dashboard.test"})
        assert cors.headers["access-control-allow-origin"] == "http://dashboard.test"
        assert "access-control-allow-origin" not in c.get("/health", headers={"Origin": "http://evil.test"}).headers

        spec = c.get("/openapi.json").json()
        assert {"/logs", "/vehicles", "/analyses", "/analyses/{analysis_id}/speed", "/health"} <= set(spec["paths"])

        missing = c.get(f"/analyses/{analysis_id}/speed", params={"event": 999})
        assert missing.status_code == 404 and missing.json()["code"] == "not_found"
        assert c.delete(f"/logs/{log['id']}").status_code == 204
        gone = c.get(f"/analyses/{analysis_id}")
        assert gone.status_code == 404 and set(gone.json()) == {"detail", "code"}
