"""Signal maps: loading, validation against a database, unit conversion, suggestions, shipped maps."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from app.errors import SignalMapError
from app.ingest import signalmap
from app.ingest.database import load_database
from app.ingest.signalmap import REQUIRED, load_signal_map, parse_signal_map, unit_factor
from app.ingest.suggest import suggest_candidates, suggest_signal_map
from app.signals.signal import Interp
from sim import units
from tests.conftest import shared_file

DBC_DIR = Path(__file__).resolve().parents[2] / "dbc"


@pytest.fixture(scope="module")
def ref_db():  # type: ignore[no-untyped-def]
    return load_database(DBC_DIR / "lashscope_ev.dbc").db


@pytest.mark.parametrize("name", ["lashscope_ev.map.toml", "lashscope_ev_1khz.map.toml"])
def test_reference_maps_resolve(ref_db, name: str) -> None:  # type: ignore[no-untyped-def]
    smap = load_signal_map(DBC_DIR / name)
    resolved = smap.resolve(ref_db)
    assert set(REQUIRED) <= set(resolved)
    assert resolved["motor_speed_rpm"].unit == "rpm" and resolved["motor_speed_rpm"].gain == 1.0
    assert resolved["brake_pressed"].interp is Interp.PREVIOUS
    assert parse_signal_map(__import__("tomllib").loads(smap.to_toml())).channels == smap.channels


REAL = [
    ("kona_pcan.map.toml", ("kona-ev", "dbc", "pcan.dbc"), {"pedal_pct": 100 / 254}),
    ("tesla_powertrain.map.toml", ("opendbc", "opendbc", "dbc", "tesla_powertrain.dbc"),
     {"vehicle_speed_kmh": 1.609344, "motor_speed_rpm": 1.0}),
    ("tesla_can.map.toml", ("opendbc", "opendbc", "dbc", "tesla_can.dbc"), {"vehicle_speed_kmh": 1.609344}),
    ("tesla_model3.map.toml", ("model3dbc", "Model3CAN.dbc"), {"motor_speed_rpm": 9.036}),
]


@pytest.mark.parametrize(("map_name", "dbc", "gains"), REAL, ids=[r[0] for r in REAL])
def test_real_vehicle_maps_validate(map_name: str, dbc: tuple[str, ...], gains: dict[str, float]) -> None:
    resolved = load_signal_map(DBC_DIR / map_name).resolve(load_database(shared_file(*dbc)).db)
    assert set(REQUIRED) <= set(resolved)
    for channel, gain in gains.items():
        assert math.isclose(resolved[channel].gain, gain, rel_tol=1e-12)


def _map(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "m.toml"
    path.write_text(text)
    return path


@pytest.mark.parametrize(("text", "match"), [
    ('[channels.motor_speed_rpm]\nmessage = "Nope"\nsignal = "MotorSpeed"\n',
     "channel motor_speed_rpm: message 'Nope' is not in the database"),
    ('[channels.motor_speed_rpm]\nmessage = "MCU_Speed"\nsignal = "Nope"\n',
     "channel motor_speed_rpm: message MCU_Speed has no signal 'Nope'"),
    ('[channels.pedal_pct]\nmessage = "MCU_Speed"\nsignal = "InverterTemp"\n',
     "channel pedal_pct: cannot convert unit 'degC' of MCU_Speed.InverterTemp to '%'"),
])
def test_validation_names_channel_message_signal(ref_db, tmp_path: Path, text: str, match: str) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(SignalMapError, match=match):
        load_signal_map(_map(tmp_path, text)).resolve(ref_db)


@pytest.mark.parametrize(("text", "match"), [
    ("[channels.motor_speed_rpm\n", "invalid TOML"),
    ('[channels.speed]\nmessage = "A"\nsignal = "B"\n', "unknown channel 'speed'"),
    ('[channels.pedal_pct]\nsignal = "B"\n', "channel pedal_pct: missing 'message'"),
    ('[channels.pedal_pct]\nmessage = "A"\nsignal = "B"\nfactor = "x"\n', "factor = 'x' has the wrong type"),
    ('[channels.pedal_pct]\nmessage = "A"\nsignal = "B"\nscale = 2\n', "unknown keys \\['scale'\\]"),
    ('[channels.pedal_pct]\nmessage = "A"\nsignal = "B"\nbus = -1\n', "bus = -1 must be >= 0"),
    ('[vehicle]\nname = "x"\n', "no \\[channels"),
])
def test_bad_map_files(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(SignalMapError, match=match):
        load_signal_map(_map(tmp_path, text))


def test_missing_map_file(tmp_path: Path) -> None:
    with pytest.raises(SignalMapError, match="cannot read"):
        load_signal_map(tmp_path / "absent.toml")


def test_conversion_invert_and_id_reference(ref_db, tmp_path: Path) -> None:  # type: ignore[no-untyped-def]
    text = ('[channels.motor_speed_rpm]\nmessage = "0x101"\nsignal = "MotorSpeed"\nunit = "rad/s"\n'
            'invert = true\nbus = 1\n[channels.motor_torque_nm]\nmessage = 256\nsignal = "MotorTorqueActual"\n'
            'factor = 2\noffset = -1.5\n')
    r = load_signal_map(_map(tmp_path, text)).resolve(ref_db)
    assert r["motor_speed_rpm"].message.name == "MCU_Speed" and r["motor_speed_rpm"].spec.bus == 1
    assert math.isclose(r["motor_speed_rpm"].gain, -60 / (2 * math.pi))
    assert (r["motor_torque_nm"].gain, r["motor_torque_nm"].offset) == (2.0, -1.5)


@pytest.mark.parametrize(("unit", "canonical", "factor"), [
    ("RPM", "rpm", 1.0), ("1/min", "rpm", 1.0), ("rad/s", "rpm", 60 / (2 * math.pi)), ("MPH", "km/h", 1.609344),
    ("m/s", "km/h", 3.6), ("KPH", "km/h", 1.0), ("N.m", "Nm", 1.0), ("kNm", "Nm", 1000.0), ("", "Nm", 1.0),
    ("degC", "rpm", None), ("bar", "%", None),
    ("m/s^2", "m/s^2", 1.0), ("m/s2", "m/s^2", 1.0), ("m/s²", "m/s^2", 1.0), ("g", "m/s^2", 9.80665),
    ("mg", "m/s^2", 9.80665e-3), ("km/h", "m/s^2", None),
])
def test_unit_factor(unit: str, canonical: str, factor: float | None) -> None:
    got = unit_factor(unit, canonical)
    assert got == factor if factor is None else math.isclose(got or 0.0, factor)


def test_suggestions_find_the_reference_signals(ref_db) -> None:  # type: ignore[no-untyped-def]
    draft = suggest_signal_map(ref_db)
    routes = draft.routes(ref_db)
    assert routes["motor_torque_nm"] == ("MCU_Torque", "MotorTorqueActual")
    assert routes["motor_speed_rpm"][1] in ("MotorSpeed", "MotorSpeedFast")
    assert routes["pedal_pct"] == ("VCU_Pedal", "AccelPedalPos")
    assert routes["vehicle_speed_kmh"] == ("ESP_Vehicle", "VehicleSpeed")
    assert routes["wheel_speed_rr_rpm"] == ("ESP_WheelSpeeds", "WheelSpeedRR")
    assert routes["accel_long_ms2"] == ("ESP_Accel", "LongAccel")
    # an observed period overrides the DBC cycle time: a slow MCU_Fast loses against the 10 ms message
    slow = suggest_candidates(ref_db, {0xA0: 0.5, 0x101: 0.01})["motor_speed_rpm"]
    assert slow[0].signal == "MotorSpeed"


def test_suggestions_on_production_dbc() -> None:
    db = load_database(shared_file("opendbc", "opendbc", "dbc", "tesla_powertrain.dbc")).db
    routes = suggest_signal_map(db).routes(db)
    assert routes["motor_speed_rpm"] == ("DI_torque1", "DI_motorRPM")
    assert routes["pedal_pct"] == ("DI_torque1", "DI_pedalPos")
    assert routes["motor_torque_nm"][0] in ("DI_torque1", "DI_torque2")


def test_the_ingest_conversion_of_rad_s_is_the_simulators() -> None:
    """app.ingest keeps its own copy of 1 rad/s in rpm so that reading a log never loads the simulator; it must be
    the simulator's to the bit."""
    assert signalmap.RPM_PER_RAD_S == units.RPM_PER_RAD_S  # that it loads neither: tests/ingest/test_cli_imports.py
