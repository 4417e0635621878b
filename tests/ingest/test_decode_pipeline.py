"""load_signals: a BLF written by python-can -> canonical signals with units, NaN, bus selection, report."""

from __future__ import annotations

from pathlib import Path

import can
import cantools
import numpy as np
import pytest

from app.errors import MissingSignalError
from app.ingest.database import load_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.readers import open_log
from app.ingest.signalmap import REQUIRED, SignalMap, load_signal_map, parse_signal_map
from app.signals.signal import Interp
from tests.conftest import shared_file

DBC_DIR = Path(__file__).resolve().parents[2] / "dbc"
START = 1_700_000_000.0


def write_reference_blf(path: Path, seconds: float = 2.0, drop_torque_alive: tuple[int, ...] = (),
                        sna_speed_at: tuple[int, ...] = (), second_bus: bool = False) -> dict[str, np.ndarray]:
    """10 ms reference-EV frames from known values; returns the physical values sent per channel."""
    db = cantools.database.load_file(str(DBC_DIR / "lashscope_ev.dbc"))
    n = int(seconds / 0.01)
    t = np.arange(n) * 0.01
    speed = np.round(2000 * np.sin(t) * 2) / 2
    torque = np.round(150 * np.cos(3 * t) * 10) / 10
    pedal = np.round(40 + 20 * np.sin(t), 0) * 0.4
    msgs = []
    for i in range(n):
        values = {
            "MCU_Speed": {"MotorSpeed": speed[i], "InverterTemp": 40, "MotorTemp": 50, "MCU_SpeedAlive": i % 15,
                          "MCU_SpeedCRC": 0},
            "MCU_Torque": {"MotorTorqueActual": torque[i], "MotorTorqueRequest": 0, "MotorTorqueState": 2,
                           "MCU_TorqueAlive": i % 15, "MCU_TorqueCRC": 0},
            "VCU_Pedal": {"AccelPedalPos": pedal[i], "BrakePedalPressed": int(i > n // 2), "DriveMode": 3,
                          "VCU_PedalAlive": i % 15, "VCU_PedalCRC": 0},
        }
        for j, (name, vals) in enumerate(values.items()):
            if name == "MCU_Torque" and i in drop_torque_alive:
                continue
            msg = db.get_message_by_name(name)
            data = bytearray(msg.encode(vals, strict=False))
            if name == "MCU_Speed" and i in sna_speed_at:
                data[0:2] = b"\x00\x80"
            msgs.append(can.Message(timestamp=START + t[i] + 0.0001 * j, arbitration_id=msg.frame_id,
                                    is_extended_id=False, data=bytes(data), channel=0))
            if second_bus and name == "MCU_Speed":
                msgs.append(can.Message(timestamp=START + t[i] + 0.0005, arbitration_id=msg.frame_id,
                                        is_extended_id=False, data=msg.encode({**vals, "MotorSpeed": 0}, strict=False),
                                        channel=1))
    with can.BLFWriter(str(path)) as w:
        for m in msgs:
            w.on_message_received(m)
    return {"motor_speed_rpm": speed, "motor_torque_nm": torque, "pedal_pct": pedal}


@pytest.fixture(scope="module")
def ref():  # type: ignore[no-untyped-def]
    return load_database(DBC_DIR / "lashscope_ev.dbc"), load_signal_map(DBC_DIR / "lashscope_ev.map.toml")


def test_values_units_and_report(tmp_path: Path, ref) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "drive.blf"
    sent = write_reference_blf(log, drop_torque_alive=(50, 51, 52), sna_speed_at=(7,))
    calls: list[tuple[float, str]] = []
    signals, report = load_signals(log, *ref, progress=lambda f, m: calls.append((f, m)), require=REQUIRED)
    speed = signals["motor_speed_rpm"]
    assert speed.unit == "rpm" and speed.interp is Interp.LINEAR and len(speed) == 200
    expected = sent["motor_speed_rpm"].copy()
    expected[7] = np.nan
    np.testing.assert_array_equal(speed.values, expected)
    assert speed.t[0] == pytest.approx(0.0, abs=1e-3) and speed.t[-1] == pytest.approx(1.99, abs=2e-3)
    np.testing.assert_allclose(signals["motor_torque_nm"].values, np.delete(sent["motor_torque_nm"], [50, 51, 52]),
                               rtol=1e-12)  # 0.1 Nm/bit: raw * 0.1 differs from the decimal literal in the last bit
    np.testing.assert_allclose(signals["pedal_pct"].values, sent["pedal_pct"], atol=1e-9)
    pressed = signals["brake_pressed"]
    assert pressed.interp is Interp.PREVIOUS and pressed.labels[1] == "Pressed"
    assert report.frames_read == 597 and report.frames_decoded == 597 and report.format == "blf"
    (gap,) = [g for g in report.counter_gaps if g.signal == "MCU_TorqueAlive"]
    assert (gap.gaps, gap.missed) == (1, 3)
    assert report.channels["motor_speed_rpm"] == 200
    assert calls and calls[-1][0] == 1.0 and all(0.0 <= f <= 1.0 for f, _ in calls)


def test_one_argument_progress_and_open_reader(tmp_path: Path, ref) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "drive.blf"
    write_reference_blf(log, seconds=0.5)
    fractions: list[float] = []
    with open_log(log) as reader:
        signals, _ = load_signals(reader, *ref, progress=lambda f, _frames: fractions.append(f))
    assert fractions[-1] == 1.0 and len(signals["pedal_pct"]) == 50


def test_bus_selection_and_inversion(tmp_path: Path, ref) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "two_buses.blf"
    sent = write_reference_blf(log, seconds=0.5, second_bus=True)
    loaded, _ = ref
    smap = parse_signal_map({"channels": {
        "motor_speed_rpm": {"message": "MCU_Speed", "signal": "MotorSpeed", "bus": 0, "invert": True},
        "motor_torque_nm": {"message": "MCU_Speed", "signal": "MotorSpeed", "bus": 1, "unit": "Nm"},
        "pedal_pct": {"message": "VCU_Pedal", "signal": "AccelPedalPos"}}})
    signals, _ = load_signals(log, loaded, smap)
    np.testing.assert_array_equal(signals["motor_speed_rpm"].values, -sent["motor_speed_rpm"][:50])
    assert np.all(signals["motor_torque_nm"].values == 0.0) and len(signals["motor_torque_nm"]) == 50


def test_missing_required_channels(tmp_path: Path, ref) -> None:  # type: ignore[no-untyped-def]
    log = tmp_path / "drive.blf"
    write_reference_blf(log, seconds=0.2)
    loaded, _ = ref
    smap = SignalMap("partial", dict(load_signal_map(DBC_DIR / "lashscope_ev.map.toml").channels))
    del smap.channels["pedal_pct"]
    with pytest.raises(MissingSignalError, match="pedal_pct: not in the signal map; motor_speed_rpm"):
        load_signals(log, loaded, parse_signal_map({"channels": {
            "motor_speed_rpm": {"message": "MCU_Speed", "signal": "MotorSpeed", "bus": 4}}}),
            require=("pedal_pct", "motor_speed_rpm"))
    with pytest.raises(MissingSignalError, match="pedal_pct: not in the signal map"):
        load_signals(log, loaded, smap, require=REQUIRED)


def test_kona_capture_with_kona_map() -> None:
    log = shared_file("kona-ev", "230112-7-2019-pcan-ccan-power-off-on-ready-off.csv")
    loaded = load_database(shared_file("kona-ev", "dbc", "pcan.dbc"))
    signals, report = load_signals(log, loaded, load_signal_map(DBC_DIR / "kona_pcan.map.toml"), require=REQUIRED)
    assert len(signals["motor_speed_rpm"]) > 1000 and len(signals["pedal_pct"]) > 1000
    assert {r.kind for r in report.database_repairs} == {"missing_bu", "missing_bs"}
    assert np.all(np.diff(signals["motor_torque_nm"].t) > 0)
    vcu = next(s for s in report.ids if s.message == "VCU_291")
    assert vcu.period_ms == pytest.approx(10.0, abs=0.1)
