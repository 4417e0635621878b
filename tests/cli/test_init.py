"""``lashscope init``: from a log and its DBC to a registered vehicle, then ``--vehicle NAME`` everywhere."""

from __future__ import annotations

import builtins
import json
import os
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from app.cli import init as init_cli
from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.settings import default_dbc_dir
from app.signal_proposal import _sign_choices, parse_overrides, propose
from app.signals import Signal, SignalSet

DBC = default_dbc_dir() / "lashscope_ev.dbc"


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("init") / "drive.blf"
    build_demo_log(path, DBC, DBC.with_name("lashscope_ev.map.toml"), Scenario(duration_s=20.0))
    return path


def _stored_map(data: Path, name: str, version: int = 1) -> dict[str, dict[str, object]]:
    text = (data / "vehicles" / name / f"v{version}" / "signals.map.toml").read_text(encoding="utf-8")
    return dict(tomllib.loads(text)["channels"])


def _lashscope(*argv: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """The installed command line in its own process, as a user runs it (default data dir ./lashscope-data)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("LASHSCOPE_")}
    return subprocess.run([sys.executable, "-m", "app", *argv], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=600)


def test_two_commands_from_a_log_and_a_dbc_to_an_analysis(log: Path, tmp_path: Path) -> None:
    """README's "Your first real log": init, then analyze with the registered name; nothing written by hand."""
    run = _lashscope("init", str(log), "--dbc", str(DBC), "--name", "my-ev", "--preset", "paper", "--yes",
                     cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    out = run.stdout
    # the evidence is printed per channel: source, unit, rate, range, correlation and sign
    row = next(line for line in out.splitlines() if line.startswith("motor_speed_rpm"))
    assert "MCU_Speed.MotorSpeed" in row and " rpm " in row and "99." in row and "+0." in row
    assert "vehicle my-ev v1 registered" in out
    assert f"next: lashscope analyze {log} --vehicle my-ev\n" in out
    data = tmp_path / "lashscope-data"
    channels = _stored_map(data, "my-ev")
    assert channels["motor_torque_nm"] == {"message": "MCU_Torque", "signal": "MotorTorqueActual"}
    assert channels["motor_speed_rpm"] == {"message": "MCU_Speed", "signal": "MotorSpeed"}
    assert channels["pedal_pct"] == {"message": "VCU_Pedal", "signal": "AccelPedalPos"}

    run = _lashscope("analyze", str(log), "--vehicle", "my-ev", "--no-whole-log", "--json", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    doc = json.loads(run.stdout)
    assert doc["vehicle"] == "my-ev"  # the registered name, not the driveline's
    assert doc["summary"]["with_metrics"] >= 4
    assert doc["ingest"]["database"] == "database.dbc"  # the registered vehicle's own copy of the DBC

    # the same files again: no new version
    run = _lashscope("init", str(log), "--dbc", str(DBC), "--name", "my-ev", "--preset", "paper", "-y", cwd=tmp_path)
    assert run.returncode == 0 and "vehicle my-ev v1 unchanged" in run.stdout, run.stderr


def test_map_overrides_and_signs_are_the_users(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    saved = tmp_path / "mine.map.toml"
    assert main(["init", str(log), "--dbc", str(DBC), "--name", "ev2", "--preset", "single_reduction", "--yes",
                 "--map", "brake_pressed=-", "--map", "vehicle_speed_kmh=ESP_Vehicle.VehicleSpeed",
                 "--invert", "wheel_speed_fl_rpm", "--save-map", str(saved), "--data-dir", str(data)]) == 0
    out = capsys.readouterr().out
    assert "ESP_Vehicle.VehicleSpeed (yours)" in out
    channels = _stored_map(data, "ev2")
    assert "brake_pressed" not in channels
    assert channels["wheel_speed_fl_rpm"]["invert"] is True
    assert "invert" not in channels["motor_speed_rpm"]  # the sign check found the speed positive
    assert tomllib.loads(saved.read_text(encoding="utf-8"))["channels"] == channels


def test_without_confirmation_nothing_is_stored(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    monkeypatch.setattr(init_cli, "_interactive", lambda: False)  # pytest's stdin is no terminal anyway
    assert main(["init", str(log), "--dbc", str(DBC), "--name", "ev", "--preset", "paper",
                 "--data-dir", str(data)]) == 2
    cap = capsys.readouterr()
    assert "motor_torque_nm" in cap.out  # the proposal is shown
    assert cap.err.strip().count("\n") == 0 and "[confirmation_required]" in cap.err
    assert not (data / "vehicles").exists()


def test_the_prompt_accepts_an_edited_map(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                          monkeypatch: pytest.MonkeyPatch) -> None:
    data = tmp_path / "data"
    answers: Iterator[str] = iter(["e", "brake_pressed=-", "pedal_pct=VCU_Pedal.NoSuchSignal", "invert brake",
                                   "", "y", "paper"])
    monkeypatch.setattr(init_cli, "_interactive", lambda: True)
    monkeypatch.setattr(builtins, "input", lambda prompt="": next(answers))
    assert main(["init", str(log), "--dbc", str(DBC), "--name", "asked", "--data-dir", str(data)]) == 0
    out = capsys.readouterr().out
    assert out.count("channel              source") == 2  # the proposal, then the edited one
    channels = _stored_map(data, "asked")
    assert "brake_pressed" not in channels and channels["pedal_pct"]["signal"] == "AccelPedalPos"
    assert "preset paper" in out


@pytest.mark.parametrize(("args", "code"), [
    (["--name", "Bad Name", "--preset", "paper"], "invalid_vehicle_name"),
    (["--name", "ev", "--preset", "nope"], "unknown_preset"),
    (["--name", "ev", "--preset", "paper", "--map", "motor_speed=MCU_Speed.MotorSpeed"], "invalid_map_override"),
    (["--name", "ev", "--preset", "paper", "--map", "motor_speed_rpm=MotorSpeed"], "invalid_map_override"),
    (["--name", "ev", "--preset", "paper", "--map", "motor_speed_rpm=MCU_Speed.Nope"], "signal_map_error"),
    (["--name", "ev", "--preset", "paper", "--map", "motor_torque_nm=-"], "signal_map_error"),
    (["--name", "ev", "--driveline", "missing.toml"], "file_not_found"),
    (["--name", "ev"], "driveline_required"),
])
def test_bad_input_is_one_line_with_a_code(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                           args: list[str], code: str) -> None:
    data = tmp_path / "data"
    assert main(["init", str(log), "--dbc", str(DBC), "--yes", "--data-dir", str(data), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"lashscope: error [{code}]") and err.count("\n") == 1, err
    assert not (data / "vehicles").exists()


def test_an_unknown_vehicle_lists_the_registered_ones_and_the_presets(log: Path, tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    data = tmp_path / "data"
    assert main(["init", str(log), "--dbc", str(DBC), "--name", "car-a", "--preset", "paper", "--yes",
                 "--data-dir", str(data)]) == 0
    capsys.readouterr()
    for argv in (["analyze", str(log)], ["diagnose", str(log)], ["identify", str(log)]):
        assert main([*argv, "--vehicle", "car-b", "--data-dir", str(data)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("lashscope: error [vehicle_not_found]") and "registered: car-a" in err
        assert "presets: chain_drive, paper" in err and "lashscope init" in err
    assert main(["live", "--interface", "virtual", "--channel", "x", "--vehicle", "paper", "--data-dir", str(data),
                 "--duration", "1"]) == 2
    assert "[vehicle_not_found]" in capsys.readouterr().err


def test_the_sign_checks_propose_inverting_a_backwards_speed_and_an_opposed_torque() -> None:
    t = np.arange(0.0, 20.0, 0.01)
    torque = 100.0 * np.sign(np.sin(2 * np.pi * t / 4.0))
    speed = 2000.0 + np.cumsum(torque) * 0.01 * 5.0  # accelerates with the torque
    sig = {"motor_torque_nm": Signal("motor_torque_nm", t, torque, "Nm"),
           "motor_speed_rpm": Signal("motor_speed_rpm", t, speed, "rpm")}
    assert _sign_choices(SignalSet(dict(sig)), {}) == {"motor_speed_rpm": False, "motor_torque_nm": False}
    backwards = {**sig, "motor_speed_rpm": Signal("motor_speed_rpm", t, -speed, "rpm")}
    assert _sign_choices(SignalSet(backwards), {}) == {"motor_speed_rpm": True, "motor_torque_nm": False}
    opposed = {**sig, "motor_torque_nm": Signal("motor_torque_nm", t, -torque, "Nm")}
    assert _sign_choices(SignalSet(opposed), {}) == {"motor_speed_rpm": False, "motor_torque_nm": True}
    assert _sign_choices(SignalSet(opposed), {"motor_torque_nm": False})["motor_torque_nm"] is False


def test_proposal_evidence_and_overrides(log: Path) -> None:
    p = propose(log, DBC, parse_overrides(["brake_pressed=-"]))
    assert "brake_pressed" not in p.smap.channels and p.missing == []
    ev = p.evidence["motor_torque_nm"]
    assert ev.source == "MCU_Torque.MotorTorqueActual" and ev.chosen_by == "suggested" and ev.score is not None
    assert ev.rate_hz == pytest.approx(100.0, rel=0.02) and ev.minimum is not None and ev.minimum < 0 < ev.maximum
    assert ev.correlation is not None and ev.correlation > 0.5 and ev.sign == "agrees with the speed"
    assert p.evidence["pedal_pct"].correlation is not None and p.evidence["pedal_pct"].correlation > 0.5
    assert p.to_dict()["signal_map_toml"].startswith("[vehicle]")


def test_simulate_takes_a_registered_vehicle(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)  # the default data directory, ./lashscope-data
    from app.settings import get_settings

    get_settings.cache_clear()
    monkeypatch.delenv("LASHSCOPE_DATA_DIR", raising=False)
    try:
        assert main(["init", str(log), "--dbc", str(DBC), "--name", "chain-car", "--preset", "chain_drive",
                     "--yes"]) == 0
        torque = tmp_path / "tq.csv"
        torque.write_text("t_s,torque_nm\n" + "".join(f"{k * 0.01:.2f},{50 if k > 50 else -20}\n"
                                                      for k in range(150)))
        capsys.readouterr()
        assert main(["simulate", str(torque), "--vehicle", "chain-car"]) == 0
        assert capsys.readouterr().out.startswith("vehicle chain_drive,")  # the registered car's driveline
        assert main(["simulate", str(torque), "--vehicle", "chain-cat"]) == 2
        err = capsys.readouterr().err
        assert "[vehicle_not_found]" in err and "registered: chain-car" in err
    finally:
        get_settings.cache_clear()


def test_a_bad_driveline_file_is_refused_before_anything_is_stored(log: Path, tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    from sim import dump_toml, load_vehicle

    bad = tmp_path / "bad.toml"
    bad.write_text(dump_toml(load_vehicle("paper")).replace("segments = 2", "segments = 100000"), encoding="utf-8")
    data = tmp_path / "data"
    assert main(["init", str(log), "--dbc", str(DBC), "--name", "ev", "--driveline", str(bad), "--yes",
                 "--data-dir", str(data)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [") and "halfshaft.segments = 100000" in err and err.count("\n") == 1
    assert not (data / "vehicles").exists()
