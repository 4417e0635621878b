"""``lashscope simulate --what-if`` answers per tip-in/tip-out event, never on a whole-log speed swing."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.settings import default_dbc_dir

DBC = default_dbc_dir() / "lashscope_ev.dbc"
MAP = default_dbc_dir() / "lashscope_ev.map.toml"


@pytest.fixture(scope="module")
def torque_csv(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """10 s of measured torque (tip-ins and tip-outs with regeneration), as README's example makes it."""
    d = tmp_path_factory.mktemp("whatif")
    log = d / "drive.blf"
    build_demo_log(log, DBC, MAP, Scenario(duration_s=10.0))
    assert main(["decode", str(log), "--dbc", str(DBC), "--map", str(MAP), "--out", str(d / "dec"),
                 "--format", "csv"]) == 0
    return d / "dec" / "signals.csv"


def _rows(out: str) -> list[tuple[float, float]]:
    rows = []
    for line in out.splitlines():
        m = re.match(r"\s*\d+ tip_(?:in|out)\s+[\d.]+\s+[\d.]+\.\.[\d.]+\s+([\d.]+)\s+([\d.]+)\s+\d+ %$", line)
        if m:
            rows.append((float(m.group(1)), float(m.group(2))))
    return rows


def test_removing_all_backlash_lowers_the_ripple_of_every_event(torque_csv: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["simulate", str(torque_csv), "--what-if", "gap=all:0"]) == 0
    out = capsys.readouterr().out
    rows = _rows(out)
    assert len(rows) >= 2
    assert all(0 < what_if < base for base, what_if in rows), out
    m = re.search(r"what-if ripple \(median over events\) ([\d.]+) rpm = (\d+) % of the baseline's ([\d.]+) rpm", out)
    assert m is not None, out
    assert float(m.group(1)) < float(m.group(3)) and 30 <= int(m.group(2)) < 90
    assert "largest peak-to-valley" not in out  # no whole-input speed swing is called ripple

    # what the whole-input figure said: the speed swings of the drive dwarf and mask the shuffle
    from app.cli.sim import _read_torque
    from sim import load_vehicle, simulate
    from sim.metrics import peak_to_valley
    from sim.whatif import parse_what_if

    t, q = _read_torque(torque_csv)
    v = load_vehicle("paper")
    base, none = simulate(v, t, q), simulate(v, t, q, what_if=parse_what_if(["gap=all:0"]))
    whole = peak_to_valley(none.t, none.motor_speed_rpm) / peak_to_valley(base.t, base.motor_speed_rpm)
    assert whole > 1.0 and max(b for b, _ in rows) < peak_to_valley(base.t, base.motor_speed_rpm)


def test_a_window_keeps_its_events(torque_csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["simulate", str(torque_csv), "--what-if", "gap=halfshaft:0.5", "--window", "0", "4"]) == 0
    out = capsys.readouterr().out
    assert "with a crossing in 0..4 s" in out and len(_rows(out)) == 2


def test_a_bad_what_if_is_refused_before_the_baseline_runs(torque_csv: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    for spec in ("gap=no_such_gap:0", "set=no.such.field:1", "torque=x"):
        assert main(["simulate", str(torque_csv), "--what-if", spec]) == 2
        cap = capsys.readouterr()
        assert cap.out == ""  # nothing simulated, not even the baseline
        assert cap.err.startswith("lashscope: error [") and cap.err.count("\n") == 1, cap.err
    assert main(["simulate", str(torque_csv), "--window", "5", "1"]) == 2
    assert "[invalid_input]" in capsys.readouterr().err


def test_plain_torque_csv_still_reads(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    t = np.arange(0.0, 5.0, 0.01)
    q = np.where((t > 1.0) & (t < 2.5), 120.0, -40.0)
    path = tmp_path / "tq.csv"
    path.write_text("t_s,torque_nm\n" + "".join(f"{a:.3f},{b:.1f}\n" for a, b in zip(t, q, strict=True)))
    assert main(["simulate", str(path), "--what-if", "gap=all:0"]) == 0
    rows = _rows(capsys.readouterr().out)
    assert len(rows) == 2 and all(w < b for b, w in rows)


def test_tolerance_answers_per_event(torque_csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    import json

    capsys.readouterr()
    assert main(["tolerance", str(torque_csv), "--n", "12", "--seed", "3", "--measured-ripple", "250", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert "event window (not detrended" in doc["metric"] and len(doc["events"]) >= 2
    for e in doc["events"]:
        b = e["ripple_rpm"]
        assert e["t_start_s"] < e["t_cross_s"] < e["t_end_s"] and b["p5"] <= b["p50"] <= b["p95"]
        assert 0.0 <= e["measured_percentile"] <= 100.0
    med = doc["median_over_events"]["ripple_rpm"]["p50"]
    assert med == pytest.approx(float(np.median([e["ripple_rpm"]["p50"] for e in doc["events"]])))
    steady = tmp_path / "steady.csv"
    steady.write_text("t_s,torque_nm\n" + "".join(f"{k * 0.01:.2f},50\n" for k in range(500)))
    assert main(["tolerance", str(steady), "--n", "5"]) == 2
    assert "[no_events]" in capsys.readouterr().err
