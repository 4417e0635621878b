"""Job artefacts stored by earlier releases -- plain JSON files where the job kinds wrote them -- answer
through the REST routes exactly as they did: a diagnosis with its report, validation and plot, a
tolerance band, a batch with its summary and per-log records, an identification's vehicle file."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from app.storage.results import write_result
from tests.api.inprocess import TestClient, in_process, stored_analysis

REPORT = {"schema": "lashscope.diagnosis/1", "vehicle": "ev", "model": "multibody",
          "split": {"seed": 0, "calibration": [0, 2], "heldout": [1, 3]}, "noise_floor": {"sigma_rpm": 0.4},
          "decision": {"status": "explained", "top": ["torque_lag"], "reason": "held-out shrink 0.6"},
          "candidates": [{"id": "torque_lag", "fit": {"params": {"torque_lag": {"tau_s": 0.012}}},
                          "heldout": {"shrink": {"value": 0.6, "lo": 0.5, "hi": 0.7}}}], "pairs": []}
SHRINK = {"value": 0.31, "lo": 0.2, "hi": 0.4}


def _write(path: Path, doc: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(doc, indent=1), encoding="utf-8")


def _done_job(store: Any, kind: str, subject: str) -> str:
    job = store.create_job(kind, subject)
    store.start_job(job.id)
    store.finish_job(job.id)
    return str(job.id)


def _setup(client: TestClient) -> tuple[Any, str, str]:
    store, analysis = stored_analysis(client, "1" * 64, "drive.log")
    store.start_job(analysis.job.id)
    store.finish_job(analysis.job.id)
    write_result(analysis.result_dir, {"summary": {}, "events": []}, {})
    return store, analysis.id, analysis.log_id


def test_a_diagnosis_and_tolerance_band_stored_as_plain_files_answer_as_before(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with in_process(data) as client:
        store, aid, log_id = _setup(client)
        did = f"{aid}--dg00c0ffee"
        job_id = _done_job(store, "diagnosis", f"{aid}/diagnoses/{did}")
        val_job = _done_job(store, "validation", f"{aid}/diagnoses/{did}/validation")
        d = data / "analyses" / aid / "diagnoses" / did
        status = {"id": did, "analysis_id": aid, "job_id": job_id, "decision": "explained",
                  "options": {"candidates": ["torque_lag"], "seed": 0, "model": "multibody"},
                  "vehicle": {"name": "ev", "version": 1}}
        _write(d / "status.json", status)
        _write(d / "report.json", REPORT)
        _write(d / "validation.json", {"log_id": log_id, "job_id": val_job, "shrink": SHRINK})
        (d / "diagnosis_events.png").write_bytes(b"\x89PNG\r\n\x1a\nold plot")
        band = {"analysis_id": aid, "n": 10, "seed": 2, "events": [{"p5": 1.0, "p50": 2.0, "p95": 3.0}]}
        _write(data / "analyses" / aid / "tolerance_n10_seed2.json", band)

        r = client.get(f"/diagnoses/{did}")
        assert r.status_code == 200, r.text
        doc = r.json()
        report = doc["report"]
        assert doc["status"] == "done" and report["split"] == REPORT["split"]
        assert {k: report["decision"][k] for k in ("status", "top", "reason")} == REPORT["decision"]
        assert report["candidates"][0]["fit"]["params"] == {"torque_lag": {"tau_s": 0.012}}
        assert report["candidates"][0]["heldout"]["shrink"] == {"value": 0.6, "lo": 0.5, "hi": 0.7}
        assert doc["options"] == status["options"] and doc["vehicle"] == {"name": "ev", "version": 1}
        assert doc["validation"]["shrink"] == SHRINK and doc["validation"]["status"] == "done"
        assert doc["plots"] == ["events"]
        png = client.get(f"/diagnoses/{did}/plots/events")
        assert png.status_code == 200 and png.content == b"\x89PNG\r\n\x1a\nold plot"
        assert client.get(f"/diagnoses/{did}/plots/residual").json()["code"] == "diagnosis_not_ready"
        assert client.get(f"/diagnoses/{did}/charts").json()["code"] == "charts_not_found"

        tol = client.get(f"/analyses/{aid}/tolerance", params={"n": 10, "seed": 2})
        assert tol.status_code == 200 and tol.json() == band
        assert client.get(f"/analyses/{aid}/tolerance/status", params={"n": 10, "seed": 2}).json()["status"] == "done"

        applied = client.post(f"/diagnoses/{did}/apply", json={"name": "ev-lag"})
        assert applied.status_code == 201, applied.text
        assert applied.json()["effects"] == {"torque_lag": {"tau_s": 0.012}}
        assert client.get(f"/diagnoses/{did}").json()["applied"]["vehicle"] == "ev-lag"


def test_a_batch_and_an_identification_stored_as_plain_files_answer_as_before(tmp_path: Path) -> None:
    data = tmp_path / "data"
    with in_process(data) as client:
        store, _, log_id = _setup(client)
        log = store.get_log(log_id)
        _done_job(store, "batch", "ba_00aa11")
        req = {"log_ids": [log_id], "filenames": ["drive.log"], "hashes": [log.sha256], "stored": [log.path.name],
               "vehicle": "ev", "vehicle_version": 1, "vehicle_id": "ev", "options": {}, "diagnose": False}
        _write(data / "jobs" / "ba_00aa11" / "request.json", req)
        summary = {"logs": 1, "ok": 1, "failed": 0, "events": 4, "analysed_now": 1, "skipped": 0, "elapsed_s": 1.5}
        _write(data / "jobs" / "ba_00aa11" / "summary.json", summary)
        _write(data / "jobs" / "ba_00aa11" / "out" / "logs" / f"{log.sha256}.json",
               {"format": 1, "log": str(log.path), "log_name": log.path.name, "status": "ok", "events": 4})
        batch = client.get("/batches/ba_00aa11")
        assert batch.status_code == 200, batch.text
        assert batch.json()["summary"] == summary and batch.json()["counts"] == {"ok": 1, "failed": 0, "pending": 0}
        rows = client.get("/batches/ba_00aa11/logs").json()["logs"]
        assert rows == [{"status": "ok", "events": 4, "log_id": log_id, "filename": "drive.log"}]

        toml = client.get("/vehicles/ev/versions/1/driveline").text
        _done_job(store, "identification", "id_00bb22")
        _write(data / "jobs" / "id_00bb22" / "request.json",
               {"log_ids": [log_id], "validate_log_ids": [], "vehicle": "ev", "vehicle_version": 1,
                "params": ["lash"], "seed": 0, "name": "ev"})
        (data / "jobs" / "id_00bb22" / "identified.toml").write_text(toml, encoding="utf-8")
        vehicle = client.get("/identifications/id_00bb22/vehicle")
        assert vehicle.status_code == 200 and vehicle.text == toml
        ident = client.get("/identifications/id_00bb22").json()
        assert ident["status"] == "done" and ident["params"] == ["lash"] and ident["result"] is None

        assert client.delete("/batches/ba_00aa11").status_code == 204
        assert client.delete("/identifications/id_00bb22").status_code == 204
        assert not (data / "jobs" / "ba_00aa11").exists() and not (data / "jobs" / "id_00bb22").exists()
        assert client.get("/batches/ba_00aa11").json()["code"] == "batch_not_found"
