"""Signal-map suggestions from a log: only messages the log carries, units as vendors write them, corners kept apart."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.cli.decode import decode_log, format_suggestions
from app.ingest.database import LoadedDatabase, load_database
from app.ingest.suggest import corner, observed, suggest_candidates, suggest_signal_map

DBC = '''VERSION ""

NS_ :

BS_:

BU_: INV VCU WSB

BO_ 2365565953 MC_Torque_And_Timer_Info: 8 INV
 SG_ INV_Commanded_Torque : 0|16@1- (0.1,0) [-3276.8|3276.7] "torque:N.m" VCU
 SG_ INV_Torque_Feedback : 16|16@1- (0.1,0) [-3276.8|3276.7] "torque:N.m" VCU

BO_ 2365564161 MC_Motor_Position_Info: 8 INV
 SG_ INV_Motor_Angle_Electrical : 0|16@1+ (0.1,0) [0|6553.5] "angle:deg" VCU
 SG_ INV_Motor_Speed : 16|16@1- (1,0) [-32768|32767] "angular_speed:rpm" VCU

BO_ 2365566977 MC_Fast_Info: 8 INV
 SG_ INV_Fast_Torque_Feedback : 16|16@1- (0.1,0) [-3276.8|3276.7] "torque:N.m" VCU
 SG_ INV_Fast_Motor_Speed : 32|16@1- (1,0) [-32768|32767] "angular_speed:rpm" VCU

BO_ 2282750722 VCU_Data: 8 VCU
 SG_ ThrottlePercent : 0|8@1+ (1,0) [0|100] "%" WSB
 SG_ VehSpd : 8|16@1+ (0.01,0) [0|300] "kph" WSB

BO_ 2550137352 WSBFL_WheelData: 8 WSB
 SG_ SpeedWheelLeftFront : 0|16@1- (0.1,0) [-3276.8|3276.7] "1/min" VCU

BO_ 2550137353 WSBFR_WheelData: 8 WSB
 SG_ SpeedWheelRightFront : 0|16@1- (0.1,0) [-3276.8|3276.7] "Nm" VCU

BO_ 2291796994 RearWheelSpeedRADS: 8 VCU
 SG_ VCU_wheelSpeed_RR : 32|32@1+ (1E-005,0) [0|42949.67295] "rads/s" WSB
 SG_ VCU_wheelSpeed_RL : 0|32@1+ (1E-005,0) [0|42949.67295] "rads/s" WSB

BO_ 2215641608 WSBFL_Sensors: 8 WSB
 SG_ FL_Speed : 32|16@1- (0.0625,0) [-2048|2047.9375] "rpm" VCU
'''

# (message, frames in the log): MC_Fast_Info is defined but never sent; WSBFL_Sensors sent too rarely
SENT = {"MC_Torque_And_Timer_Info": 100, "MC_Motor_Position_Info": 100, "VCU_Data": 50, "WSBFL_WheelData": 50,
        "WSBFR_WheelData": 50, "RearWheelSpeedRADS": 50, "WSBFL_Sensors": 5}


@pytest.fixture
def car(tmp_path: Path) -> tuple[LoadedDatabase, Path]:
    dbc = tmp_path / "car.dbc"
    dbc.write_text(DBC)
    loaded = load_database(dbc)
    lines = []
    for name, n in SENT.items():
        msg = loaded.db.get_message_by_name(name)
        period_ms = 2000 // n
        for k in range(n):
            lines.append((k * period_ms, msg.frame_id, "00" * 8))
    log = tmp_path / "LOGS1.TXT"  # the TCU text format: hex ms, 'x', 29-bit ID, data
    log.write_text("".join(f"{t:08X}x{i:08X}{d}\n" for t, i, d in sorted(lines)))
    return loaded, log


def test_suggested_map_from_the_log(car: tuple[LoadedDatabase, Path]) -> None:
    loaded, log = car
    report = decode_log(log, loaded)
    periods, counts = observed(report.ids)
    assert counts[0x0CFFAC01] == 100 and counts[0x04100208] == 5 and 0x0CFFB001 not in counts
    routes = suggest_signal_map(loaded.db, periods, counts=counts).routes(loaded.db)
    assert routes == {
        "motor_torque_nm": ("MC_Torque_And_Timer_Info", "INV_Torque_Feedback"),
        "motor_speed_rpm": ("MC_Motor_Position_Info", "INV_Motor_Speed"),
        "pedal_pct": ("VCU_Data", "ThrottlePercent"),
        "vehicle_speed_kmh": ("VCU_Data", "VehSpd"),
        "wheel_speed_fl_rpm": ("WSBFL_WheelData", "SpeedWheelLeftFront"),
        "wheel_speed_rl_rpm": ("RearWheelSpeedRADS", "VCU_wheelSpeed_RL"),
        "wheel_speed_rr_rpm": ("RearWheelSpeedRADS", "VCU_wheelSpeed_RR"),
    }
    cands = suggest_candidates(loaded.db, periods, counts=counts)
    assert all(c.message not in ("MC_Fast_Info", "WSBFL_Sensors") for cs in cands.values() for c in cs)
    # the front-right signal's unit does not convert: not good enough for the draft, and never another corner
    assert [(c.signal, c.score) for c in cands["wheel_speed_fr_rpm"]] == [("SpeedWheelRightFront", 4.0)]
    assert [c.signal for c in cands["wheel_speed_fl_rpm"]] == ["SpeedWheelLeftFront"]
    torque = cands["motor_torque_nm"][0]
    assert torque.score == 9.0 and "unit 'torque:N.m'" in torque.reasons and "period 20 ms" in torque.reasons
    text = format_suggestions(loaded, report)
    assert "MC_Fast_Info" not in text and "with >= 20 frames in the log" in text


def test_without_a_log_every_message_is_considered(car: tuple[LoadedDatabase, Path]) -> None:
    loaded, _ = car
    cands = suggest_candidates(loaded.db)
    assert {c.message for c in cands["motor_torque_nm"]} >= {"MC_Fast_Info", "MC_Torque_And_Timer_Info"}
    assert [c.signal for c in cands["wheel_speed_fl_rpm"]] == ["SpeedWheelLeftFront", "FL_Speed"]


@pytest.mark.parametrize(("name", "where"), [
    ("SpeedWheelLeftFront", "fl"), ("VCU_wheelSpeed_RR", "rr"), ("WhlSpd_RL", "rl"), ("FRSpeedKPH", "fr"),
    ("WSBFL_Sensors", "fl"), ("RearWheelSpeedRADS", "r"), ("wheel_speed_rear_right", "rr"),
    ("ESP_WheelSpeeds", None), ("LeftTurnLamp", "-l"), ("INV_Motor_Speed", None),
])
def test_corner_from_names(name: str, where: str | None) -> None:
    assert corner(name) == where


def test_demo_log_suggestions_skip_messages_it_does_not_carry(tmp_path: Path) -> None:
    from app.demo.build import build_demo_log
    from app.demo.scenario import Scenario

    dbc = Path(__file__).resolve().parents[2] / "dbc"
    path = tmp_path / "demo.blf"
    build_demo_log(path, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml", Scenario(duration_s=10.0))
    loaded = load_database(dbc / "lashscope_ev.dbc")
    report = decode_log(path, loaded)
    periods, counts = observed(report.ids)
    assert 0xA0 not in counts  # MCU_Fast is in the DBC, not on this log
    routes = suggest_signal_map(loaded.db, periods, counts=counts).routes(loaded.db)
    assert routes["motor_speed_rpm"] == ("MCU_Speed", "MotorSpeed")
    assert routes["motor_torque_nm"] == ("MCU_Torque", "MotorTorqueActual")
    assert routes["pedal_pct"] == ("VCU_Pedal", "AccelPedalPos")
    assert {routes[f"wheel_speed_{c}_rpm"][1] for c in ("fl", "fr", "rl", "rr")} == {
        "WheelSpeedFL", "WheelSpeedFR", "WheelSpeedRL", "WheelSpeedRR"}
    assert all(routes[f"wheel_speed_{c}_rpm"][1] == f"WheelSpeed{c.upper()}" for c in ("fl", "fr", "rl", "rr"))


def test_decode_report_sampling_per_channel(car: tuple[LoadedDatabase, Path], tmp_path: Path) -> None:
    """A bursty inverter stream (1, 1, 61 ms gaps) and a periodic pedal: the report says which is which."""
    from dataclasses import asdict

    from app.cli.decode import format_channels, format_report
    from app.ingest.pipeline_signals import load_signals
    from app.ingest.signalmap import ChannelSpec, SignalMap

    loaded, _ = car
    rows = []
    for k in range(100):
        for j in range(3):
            rows.append((63 * k + j, 0x0CFFAC01))
    rows += [(50 * k, 0x08100302) for k in range(126)]
    log = tmp_path / "LOGS2.TXT"
    log.write_text("".join(f"{t:08X}x{i:08X}0000000000000000\n" for t, i in sorted(rows)))
    smap = SignalMap("car", {"motor_torque_nm": ChannelSpec("motor_torque_nm", "MC_Torque_And_Timer_Info",
                                                             "INV_Torque_Feedback"),
                             "pedal_pct": ChannelSpec("pedal_pct", "VCU_Data", "ThrottlePercent")})
    signals, report = load_signals(log, loaded, smap)
    torque, pedal = report.sampling["motor_torque_nm"], report.sampling["pedal_pct"]
    assert torque.samples == 300 and torque.bursty
    assert (torque.median_ms, torque.max_ms) == (pytest.approx(1.0), pytest.approx(61.0))
    assert torque.mean_ms == pytest.approx((63 * 99 + 2) / 299)
    assert (pedal.samples, pedal.bursty) == (126, False)
    assert (pedal.mean_ms, pedal.median_ms) == (pytest.approx(50.0), pytest.approx(50.0))
    ids = {s.message: s for s in report.ids}
    assert ids["MC_Torque_And_Timer_Info"].bursty and not ids["VCU_Data"].bursty
    assert ids["MC_Torque_And_Timer_Info"].median_gap_ms == 1.0 and ids["VCU_Data"].p95_gap_ms == 50.0
    plain = asdict(report)  # what the API stores and returns for a log
    assert plain["sampling"]["motor_torque_nm"]["bursty"] is True
    assert plain["ids"][0]["median_gap_ms"] is not None
    assert "motor_torque_nm: median spacing 1 ms" in format_channels(signals)
    assert "MC_Torque_And_Timer_Info: median spacing 1 ms" in format_report(report)



def _mg_dbc(speed: str) -> str:
    """A motor-generator's messages with its speed signal written as ``speed`` (a DBC SG_ line's name..unit
    part, optionally followed by a comment line)."""
    line, _, comment = speed.partition("\n")
    return f'''VERSION ""

NS_ :

BS_:

BU_: MG VCU

BO_ 272 MG_Status: 8 MG
 SG_ {line} VCU
 SG_ MG_OutputTorque : 16|16@1- (0.1,0) [-3276.8|3276.7] "Nm" VCU
 SG_ MG_Temperature : 32|8@1+ (1,-40) [-40|215] "degC" VCU
 SG_ MG_Voltage : 40|16@1+ (0.1,0) [0|1000] "V" VCU

BO_ 784 VCU_Vehicle: 8 VCU
 SG_ VehicleSpeed : 0|16@1+ (0.01,0) [0|300] "km/h" MG

{comment}
BA_DEF_ BO_  "GenMsgCycleTime" INT 0 10000;
BA_ "GenMsgCycleTime" BO_ 272 10;
BA_ "GenMsgCycleTime" BO_ 784 100;
'''


@pytest.mark.parametrize(("speed", "signal", "why"), [
    ('MG_OutputRevolution : 0|16@1- (1,0) [-20000|20000] "rpm"', "MG_OutputRevolution", "name has 'revolution'"),
    ('MG_Out1 : 0|16@1- (1,0) [-20000|20000] "rpm"', "MG_Out1", "unit 'rpm' is a rotational speed"),
    ('MG_Out1 : 0|16@1- (0.1,0) [-2000|2000] "rad/s"', "MG_Out1", "unit 'rad/s' is a rotational speed"),
    ('MG_Out1 : 0|16@1- (1,0) [-20000|20000] ""\nCM_ SG_ 272 MG_Out1 "Motor-generator output shaft, in 1/min";',
     "MG_Out1", "comment gives the unit '1/min'"),
])
def test_rotational_speed_units_find_the_motor_speed(tmp_path: Path, speed: str, signal: str, why: str) -> None:
    """``MG_OutputRevolution [rpm]`` was missed: no speed word the suggester knew, and the unit was not read as
    the speed it is. A rotational-speed unit (the signal's, or written in its comment) now stands in for the
    word; torque, temperature, voltage and the vehicle speed stay out of the motor speed's candidates."""
    dbc = tmp_path / "mg.dbc"
    dbc.write_text(_mg_dbc(speed))
    db = load_database(dbc).db
    cands = suggest_candidates(db)["motor_speed_rpm"]
    assert cands[0].signal == signal and why in cands[0].reasons, cands[0]
    assert {c.signal for c in cands} <= {signal}  # nothing else of the motor-generator is a speed
    smap = suggest_signal_map(db)
    assert smap.channels["motor_speed_rpm"].signal == signal
    assert smap.channels["motor_torque_nm"].signal == "MG_OutputTorque"
    assert smap.channels["vehicle_speed_kmh"].signal == "VehicleSpeed"
