"""The command line on the same pipeline: ``lashscope analyze --json`` and ``lashscope demo``."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import pytest

from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.settings import default_dbc_dir

DBC = default_dbc_dir()


@pytest.fixture(scope="module")
def short_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "short.blf"
    build_demo_log(path, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml", Scenario(duration_s=20.0))
    return path


def test_demo_log_is_deterministic(short_log: Path, tmp_path: Path) -> None:
    again = tmp_path / "again.blf"
    build_demo_log(again, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml", Scenario(duration_s=20.0))
    assert hashlib.sha256(again.read_bytes()).digest() == hashlib.sha256(short_log.read_bytes()).digest()


def test_demo_alive_counters_count_and_show_the_dropped_frames(short_log: Path) -> None:
    from app.pipeline import decode_log

    _, ingest = decode_log(short_log, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml")
    gaps = {g["message"]: g for g in ingest["decode"]["counter_gaps"]}
    assert set(gaps) == {"MCU_Torque", "MCU_Speed", "VCU_Pedal", "ESP_Vehicle"}
    for g in gaps.values():
        assert g["kind"] == "step" and g["pattern"] == "step +1 mod 15"
        assert g["gaps"] == g["missed"] == Scenario().dropped_frames  # each dropped frame is one missed count


def test_one_analysis_compiles_the_vehicle_once(short_log: Path, chain_builds: list[str]) -> None:
    """The driveline chain is compiled once per vehicle, not once per simulation (it was N + 3 times for N
    analysed events: each event, the whole log, and two inertias)."""
    from app.pipeline import VehicleInputs, run_analysis
    from sim import load_vehicle

    inputs = VehicleInputs(load_vehicle("paper"), DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml")
    res = run_analysis(short_log, inputs)
    simulated = [r for r in res.event_results if r.aligned is not None]
    assert len(simulated) >= 4 and res.whole is not None
    assert chain_builds == ["paper"]
    run_analysis(short_log, inputs)  # the same vehicle again: nothing to build
    assert chain_builds == ["paper"]


def test_analyze_json(short_log: Path, capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "result.json"
    assert main(["analyze", str(short_log), "--vehicle", "paper", "--gap-sensitivity", "--json", "--out",
                 str(out)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc == json.loads(out.read_text())
    assert doc["vehicle"] == "paper" and doc["summary"]["with_metrics"] >= 4
    assert doc["ingest"]["format"] == "blf" and "motor_speed_rpm" in doc["ingest"]["channels"]
    # the demo's 100 Hz ESP accelerometer decodes, passes the check against the road speed, feeds the criteria
    assert "accel_long_ms2" in doc["ingest"]["channels"]
    assert doc["acceleration"]["kind"] == "accelerometer" and doc["acceleration"]["check"]["verdict"] == "ok"
    assert doc["acceleration"]["check"]["offset_ms2"] == pytest.approx(Scenario().accel_offset_ms2, abs=0.03)
    assert doc["summary"]["drivability"]["shuffle_pp_ms2"]["events"] >= 4
    assert {"measured", "simulated", "difference", "rms_rpm", "nrmse"} <= set(doc["metrics"][0])
    sens = doc["gap_sensitivity"]
    assert sens["sensitivity_unit"] == "mm" and sens["gaps"][-1]["sensitivity_per_rad"] == pytest.approx(100.0)


def test_analyze_tolerance(short_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(short_log), "--vehicle", "paper", "--no-whole-log", "--tolerance", "24",
                 "--seed", "2", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    tol = doc["tolerance"]
    assert tol["n"] == 24 and tol["seed"] == 2 and len(tol["events"]) == doc["summary"]["with_metrics"] >= 4
    for e in tol["events"]:
        b = e["band_rpm"]
        assert e["error"] is None and b["p5"] <= b["p50"] <= b["p95"]
        assert 0.0 <= e["measured_percentile"] <= 100.0 and e["measured_fluctuation_rpm"] >= 0.0
        # the percentile agrees with the band: below p5 -> under ~5 %, above p95 -> over ~95 %
        if e["measured_fluctuation_rpm"] < b["p5"]:
            assert e["measured_percentile"] <= 5.0 + 100.0 / 24
        if e["measured_fluctuation_rpm"] > b["p95"]:
            assert e["measured_percentile"] >= 95.0 - 100.0 / 24
    assert main(["analyze", str(short_log), "--vehicle", "paper", "--no-whole-log", "--tolerance", "8"]) == 0
    assert "tolerance band, 8 variants per event" in capsys.readouterr().out


def test_analyze_errors_are_one_line_with_code(short_log: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(short_log), "--vehicle", "no-such-preset"]) == 2
    assert capsys.readouterr().err.startswith("lashscope: error [")


def test_demo_builds_analyses_plots_and_stores(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["demo", "--data-dir", str(tmp_path)]) == 0
    text = capsys.readouterr().out
    assert "analysed" in text and "fluctuation peak-valley" in text
    assert "alive counter" in text and "MCU_Torque.MCU_TorqueAlive" in text and "step +1 mod 15" in text
    png = tmp_path / "demo" / "overlay.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20000
    from app.storage import SQLiteStore

    store = SQLiteStore(tmp_path)
    (analysis,) = store.list_analyses()
    assert analysis.job.status.value == "done" and analysis.summary["with_metrics"] >= 20
    store.close()
    assert f"dashboard:     http://127.0.0.1:8000/#/analysis/{analysis.id}" in text  # the page that shows it
    _check_overlay_layout(analysis.result_dir)


def _check_overlay_layout(result_dir: Path) -> None:
    """No figure-level label or title overlaps a panel (axes with its tick labels and title)."""
    import matplotlib.pyplot as plt

    from app.demo.plot import overlay_figure
    from app.storage.results import ResultFiles

    fig = overlay_figure(ResultFiles(result_dir))
    try:
        renderer = fig.canvas.get_renderer()  # type: ignore[attr-defined]
        fig.canvas.draw()
        boxes = [ax.get_tightbbox(renderer) for ax in fig.axes if ax.get_visible() and ax.axison]
        panels = [b for b in boxes if b is not None]
        labels = [t.get_window_extent(renderer) for t in fig.texts]  # suptitle, supxlabel, supylabel
        assert len(panels) == 12 and len(labels) == 3
        for lab in labels:
            for box in panels:
                assert not lab.overlaps(box), (lab, box)
    finally:
        plt.close(fig)


HEAVY = ("fastapi", "uvicorn", "starlette", "numba", "sim", "matplotlib", "pandas", "scipy", "numpy", "can", "cantools")


def test_registering_serve_analyze_demo_imports_nothing_heavy() -> None:
    """Every invocation registers every command: the dispatcher and these commands' register() stay light."""
    import subprocess
    import sys

    code = ("import argparse, sys\n"
            "import app.cli\n"
            "from app.cli import analyze, demo, serve\n"
            "sub = argparse.ArgumentParser().add_subparsers()\n"
            "for m in (serve, analyze, demo):\n"
            "    m.register(sub)\n"
            f"print(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r}))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=DBC.parent).stdout
    assert out.strip() == "[]"


def test_an_error_from_the_simulator_is_still_one_line(short_log: Path, capsys: pytest.CaptureFixture[str],
                                                       tmp_path: Path) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\n[halfshaft]\nstiffness = -5.0\n', encoding="utf-8")
    assert main(["analyze", str(short_log), "--vehicle", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [invalid_parameter]") and "Traceback" not in err
