"""A job that cannot finish is killed after LASHSCOPE_JOB_TIMEOUT_S while the API keeps answering;
a driveline too costly to simulate is refused at upload, naming the field."""

from __future__ import annotations

import time
from pathlib import Path

import httpx
import pytest

from sim import dump_toml, load_vehicle
from tests.api.conftest import Server, create_vehicle, upload


def costly_driveline() -> str:
    """Every value inside the loader's bounds, but the input shaft's mode needs ~2e6 steps per second."""
    text = dump_toml(load_vehicle("paper"))
    for old, new in (("mesh2_stiffness = 3000000.0", "mesh2_stiffness = 1e9"),
                     ("input_shaft_inertia = 0.0015", "input_shaft_inertia = 1e-6")):
        assert old in text
        text = text.replace(old, new)
    return text


def test_costly_vehicle_refused_with_the_field(server: Server) -> None:
    with httpx.Client(base_url=server.url, timeout=60.0) as c:
        r = c.post("/vehicles", data={"name": "stiff"},
                   files={"driveline": ("stiff-car.toml", costly_driveline().encode())})
        assert r.status_code == 422, r.text
        body = r.json()
        assert body["code"] == "invalid_parameter"
        assert "reducer.input_shaft_inertia" in body["detail"] and "stiff-car.toml" in body["detail"]
        assert "integrator steps" in body["detail"]
        assert c.get("/vehicles/stiff").status_code == 404


def test_job_timeout_fails_the_job_and_health_answers(tmp_path: Path, demo_log: Path,
                                                      monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LASHSCOPE_JOB_TIMEOUT_S", "0.5")  # the worker's imports alone take longer
    srv = Server(tmp_path / "data").start()
    try:
        with httpx.Client(base_url=srv.url, timeout=60.0) as c:
            create_vehicle(c)
            log_id = upload(c, demo_log).json()["id"]
            analysis = c.post("/analyses", json={"log_id": log_id, "vehicle": "ev"}).json()
            deadline = time.monotonic() + 60.0
            health_checks = 0
            while True:
                # a blocked server would raise a timeout here: /health must answer while the job runs
                assert c.get("/health", timeout=5.0).status_code == 200
                health_checks += 1
                body = c.get(f"/analyses/{analysis['id']}").json()
                if body["status"] in ("done", "failed") or time.monotonic() > deadline:
                    break
                time.sleep(0.05)
            assert body["status"] == "failed", body
            assert body["job"]["error"]["code"] == "timeout"
            assert "timed out after 0.5 s" in body["job"]["error"]["detail"]
            assert health_checks >= 1
            r = c.get(f"/analyses/{analysis['id']}/metrics")
            assert r.status_code == 422 and "timed out" in r.json()["detail"]
            assert c.get("/health", timeout=5.0).json()["status"] == "ok"
    finally:
        srv.stop()
