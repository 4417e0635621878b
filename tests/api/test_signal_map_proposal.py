"""POST /vehicles/signal-map-proposal: the map ``lashscope init`` proposes, for the dashboard's registration form."""

from __future__ import annotations

from pathlib import Path

from app.settings import default_dbc_dir
from tests.api.conftest import upload
from tests.api.inprocess import in_process

DBC = default_dbc_dir() / "lashscope_ev.dbc"


def test_proposal_then_registration_with_the_uploaded_files(tmp_path: Path, demo_log: Path) -> None:
    with in_process(tmp_path / "data") as c:
        log_id = upload(c, demo_log).json()["id"]  # type: ignore[arg-type]
        dbc = DBC.read_bytes()
        r = c.post("/vehicles/signal-map-proposal", data={"log_id": log_id, "map": "brake_pressed=-\n"
                                                          "invert wheel_speed_fl_rpm\n"},
                   files={"dbc": ("my car.dbc", dbc, "application/octet-stream")})
        assert r.status_code == 200, r.text
        doc = r.json()
        assert doc["log_id"] == log_id and doc["database"] == "my car.dbc" and doc["missing"] == []
        by = {ch["channel"]: ch for ch in doc["channels"]}
        assert "brake_pressed" not in by and by["wheel_speed_fl_rpm"]["invert"] is True
        speed = by["motor_speed_rpm"]
        assert speed["source"] == "MCU_Speed.MotorSpeed" and speed["unit"] == "rpm"
        assert 95.0 < speed["rate_hz"] < 105.0 and speed["correlation"] > 0.5 and speed["minimum"] > 0
        toml = doc["signal_map_toml"]
        assert "[channels.motor_torque_nm]" in toml and "brake_pressed" not in toml

        r = c.post("/vehicles", data={"name": "mine", "preset": "paper"},
                   files={"dbc": ("my car.dbc", dbc, "application/octet-stream"),
                          "signal_map": ("map.toml", toml.encode(), "application/toml")})
        assert r.status_code == 201, r.text
        assert r.json()["summary"]["channels"]["motor_speed_rpm"] == "MCU_Speed.MotorSpeed"

        for data, status, code in (({"log_id": "lg_nope"}, 404, "not_found"),
                                   ({}, 400, "invalid_input"),
                                   ({"log_id": log_id, "map": "speed=MCU_Speed.MotorSpeed"}, 400,
                                    "invalid_map_override"),
                                   ({"log_id": log_id, "map": "invert wheels"}, 400, "invalid_map_override"),
                                   ({"log_id": log_id, "map": "motor_speed_rpm=MCU_Speed.Nope"}, 422,
                                    "signal_map_error")):
            r = c.post("/vehicles/signal-map-proposal", data=data)
            assert (r.status_code, r.json()["code"]) == (status, code), r.text
