"""``lashscope identify``: logs in, an identified vehicle file out, the summary, and one-line errors."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest

from app.cli import main
from sim import load_vehicle
from tests.identify.drives import write_drive_log


def test_identify_writes_the_identified_vehicle_with_its_provenance(tmp_path: Path,
                                                                    capsys: pytest.CaptureFixture[str]) -> None:
    # logged at 200 Hz: these drives cross the lash in ~19 ms, under two samples of a 100 Hz channel (which leaves the
    # lash at the file's value, test_fit's slow-channel test)
    a = write_drive_log(tmp_path / "a.blf", {"lash": 1.3}, 41, duration_s=30.0, period_s=0.005)
    b = write_drive_log(tmp_path / "b.blf", {"lash": 1.3}, 42, duration_s=30.0, period_s=0.005)
    out = tmp_path / "paper_identified.toml"
    assert main(["identify", str(a), "--vehicle", "paper", "--out", str(out), "--validate", str(b), "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "total lash at the motor" in text and "OFF THE FILE" in text and "off the file: lash" in text
    assert "withheld drive: NRMSE" in text
    identified = load_vehicle(out)  # the [provenance] table is read past
    file = load_vehicle("paper")
    assert identified.gap("halfshaft").nominal == pytest.approx(1.3 * file.gap("halfshaft").nominal, rel=0.05)
    prov = tomllib.loads(out.read_text(encoding="utf-8"))["provenance"]
    assert prov["logs"][0]["name"] == "a.blf" and len(prov["logs"][0]["sha256"]) == 64
    assert prov["fitted"]["lash"]["ratio"] == pytest.approx(1.3, rel=0.05)
    assert main(["vehicles", "compare", "paper", str(out), "--json"]) == 0  # what moved, and where it came from
    cmp = json.loads(capsys.readouterr().out)
    figures = {f["key"]: f["ratio"] for f in cmp["figures"]}
    assert figures["lash"] == pytest.approx(prov["fitted"]["lash"]["ratio"], rel=1e-4)
    assert cmp["provenance"]["a"] is None and cmp["provenance"]["b"]["logs"][0]["name"] == "a.blf"
    assert main(["identify", str(a), "--vehicle", "paper", "--out", str(tmp_path / "j.toml"), "--json",
                 "--quiet", "--params", "lash,mass"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["named"] == ["lash"] and not doc["params"]["stiffness"]["identified"]
    assert doc["params"]["stiffness"]["note"] == "not fitted"


def test_identify_errors_are_one_line_and_write_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    short = write_drive_log(tmp_path / "short.blf", {}, 43, duration_s=6.0)
    out = tmp_path / "x.toml"
    assert main(["identify", str(short), "--vehicle", "paper", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [insufficient_data]") and "Traceback" not in err
    assert not out.exists()
    assert main(["identify", str(short), "--vehicle", "paper", "--params", "colour", "--quiet"]) == 2
    assert "[invalid_input]" in capsys.readouterr().err


def test_a_torque_channel_that_reads_high_is_written_as_the_motor_torque_gain(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """The logged torque is 1/0.9 of the air-gap torque (an inverter's estimate that reads high): the fitted gain
    goes into the new version as ``[motor] torque_gain``, and the withheld drive tracks better with it. Without the
    gain written, the identified version tracked the withheld drive no better than the file."""
    truth = load_vehicle("paper").with_changes({"motor.torque_gain": 0.9})
    a = write_drive_log(tmp_path / "a.blf", {}, 43, duration_s=30.0, vehicle=truth)
    b = write_drive_log(tmp_path / "b.blf", {}, 44, duration_s=30.0, vehicle=truth)
    out = tmp_path / "paper_identified.toml"
    assert main(["identify", str(a), "--vehicle", "paper", "--out", str(out), "--validate", str(b), "--quiet",
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    gain = doc["params"]["torque_gain"]
    assert gain["value"] == pytest.approx(0.9, rel=0.01) and gain["hi"] < 1.0 and not gain["at_bound"]
    assert doc["torque_gain_written"] == pytest.approx(gain["value"])
    assert load_vehicle(out).motor.torque_gain == pytest.approx(gain["value"])
    v = doc["validation"]
    assert v["nrmse_after"] < 0.5 * v["nrmse_before"]
    assert main(["identify", str(a), "--vehicle", "paper", "--out", str(tmp_path / "s.toml"), "--quiet"]) == 0
    assert "reads 1.11x the air-gap torque: the new version carries torque_gain = 0.89" in capsys.readouterr().out


def test_a_right_torque_gain_is_not_written(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """On a drive logged with the air-gap torque itself the file's gain stays: the new version reads 1."""
    a = write_drive_log(tmp_path / "a.blf", {"mass": 1.1}, 45, duration_s=30.0)
    out = tmp_path / "paper_identified.toml"
    assert main(["identify", str(a), "--vehicle", "paper", "--out", str(out), "--quiet", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["torque_gain_written"] is None and doc["params"]["torque_gain"]["lo"] <= 1.0
    assert load_vehicle(out).motor.torque_gain == 1.0
