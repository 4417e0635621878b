"""``lashscope decode``: tables written, report printed, map suggestions, typed errors without tracebacks."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from app.cli import main
from tests.conftest import shared_file
from tests.ingest.test_decode_pipeline import write_reference_blf

DBC_DIR = Path(__file__).resolve().parents[2] / "dbc"


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "drive.blf"
    write_reference_blf(path, seconds=1.0, drop_torque_alive=(20,), sna_speed_at=(3,))
    return path


def test_decode_with_map_writes_tables_and_report(log: Path, tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", str(log), "--dbc", str(DBC_DIR / "lashscope_ev.dbc"),
                 "--map", str(DBC_DIR / "lashscope_ev.map.toml"), "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    assert "frames read 299, decoded 299" in out
    assert re.search(r"0x100\s+MCU_Torque\s+99\s+10\.102\s+1\.005\s+10\.000/20\.000\s+10\.000/10\.000\s+10\n", out)
    assert "MCU_Torque.MCU_TorqueAlive (99 frames): step +1 mod 15 (fits 99.0%): 1 gaps, 1 frames missed" in out
    assert "skipped or corrupt regions: none" in out
    table = pq.read_table(tmp_path / "signals.parquet").to_pandas()
    speed = table[table["channel"] == "motor_speed_rpm"]
    assert len(speed) == 100 and np.isnan(speed["value"].iloc[3]) and set(speed["unit"]) == {"rpm"}
    csv = pacsv.read_csv(tmp_path / "signals.csv").to_pandas()
    assert len(csv) == len(table)


def test_decode_without_map_suggests(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", str(log), "--dbc", str(DBC_DIR / "lashscope_ev.dbc"), "--out", str(tmp_path),
                 "--format", "csv"])
    out = capsys.readouterr().out
    assert code == 0
    assert "signal map candidates" in out and "MCU_Torque.MotorTorqueActual [Nm]" in out
    assert "[channels.motor_torque_nm]" in out
    speed = pacsv.read_csv(tmp_path / "messages" / "MCU_Speed.csv").to_pandas()
    assert list(speed.columns[:3]) == ["t_s", "bus", "MotorSpeed"] and len(speed) == 100
    assert not (tmp_path / "messages" / "MCU_Speed.parquet").exists()


def test_kona_interleaved_buses_are_a_timestamp_note_not_a_skipped_region(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = shared_file("kona-ev", "221217-1-2021-pcan-bcan-no-key.csv")
    code = main(["decode", str(log), "--dbc", str(shared_file("kona-ev", "dbc", "pcan.dbc")),
                 "--map", str(DBC_DIR / "kona_pcan.map.toml"), "--out", str(tmp_path)])
    out = capsys.readouterr().out
    assert code == 0
    section = out[out.index("timestamp anomalies:"):]
    assert section.startswith("timestamp anomalies:\n  per bus: none\n  in file order (all buses): 1029 backward steps")
    assert "none within a bus: the buses are logged interleaved" in section
    assert "skipped or corrupt regions: none" in section and "time_backwards" not in out


def test_backwards_step_within_one_bus_is_listed_per_bus(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "back.log"
    times = [1.0, 1.01, 1.02, 1.005, 1.03, 1.04]
    log.write_text("".join(f"({t:.6f}) can0 100#0011223344556677\n" for t in times))
    code = main(["decode", str(log), "--dbc", str(DBC_DIR / "lashscope_ev.dbc"), "--out", str(tmp_path / "o")])
    out = capsys.readouterr().out
    assert code == 0
    # times count from the log's start
    assert "  per bus: backwards 1\n    backwards: bus 0 frame 3 at 0.005000 s (step -0.015000 s)" in out
    assert "in file order (all buses): 1 backward steps (first before frame index 3); the per-bus steps above" in out
    assert "skipped or corrupt regions: none" in out


def test_report_lists_damaged_regions(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "cut.blf"
    broken.write_bytes(log.read_bytes()[: log.stat().st_size * 2 // 3])
    code = main(["decode", str(broken), "--dbc", str(DBC_DIR / "lashscope_ev.dbc"),
                 "--map", str(DBC_DIR / "lashscope_ev.map.toml")])
    out = capsys.readouterr().out
    assert code == 0
    assert "skipped or corrupt regions:\n  byte " in out


@pytest.mark.parametrize(("args", "message"), [
    (["--dbc", "{missing}"], "database_error"),
    (["--dbc", "{dbc}", "--map", "{missing}"], "signal_map_error"),
    (["--dbc", "{dbc}", "--format", "xlsx"], "invalid_input"),
    (["--dbc", "{kona}", "--map", "{map}"], "signal_map_error"),
])
def test_errors_are_one_line(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str],
                             message: str) -> None:
    values = {"missing": str(tmp_path / "nope"), "dbc": str(DBC_DIR / "lashscope_ev.dbc"),
              "map": str(DBC_DIR / "lashscope_ev.map.toml"), "kona": str(shared_file("kona-ev", "dbc", "pcan.dbc"))}
    code = main(["decode", str(log), *[a.format(**values) for a in args]])
    err = capsys.readouterr().err
    assert code == 2 and f"[{message}]" in err and "Traceback" not in err and err.count("\n") == 1


def test_missing_log_is_file_not_found(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", str(tmp_path / "nope.blf"), "--dbc", str(DBC_DIR / "lashscope_ev.dbc")])
    err = capsys.readouterr().err
    assert code == 2 and "[file_not_found]" in err and "nope.blf" in err and err.count("\n") == 1


def test_strict_refuses_broken_dbc(log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["decode", str(log), "--dbc", str(shared_file("kona-ev", "dbc", "pcan.dbc")), "--strict"])
    err = capsys.readouterr().err
    assert code == 2 and "pcan.dbc:6: cannot load DBC" in err
