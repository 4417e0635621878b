"""The fleet report: per-vehicle lash and ripple with intervals, the fleet band, flags, the plot; the hook."""

from __future__ import annotations

import json
import math
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from app.fleet.report import fleet_report, report_png
from app.fleet.store import read_events, write_rows


def _vehicle_rows(name: str, gap_ms: float, rise_rpm: float, ripple_rpm: float, seed: int) -> list[dict[str, Any]]:
    rng = np.random.default_rng(seed)
    start = datetime(2025, 5, 5, 8, tzinfo=UTC)  # Monday
    rows = []
    for k in range(20):  # 10 days, two events a day
        t = start + timedelta(hours=12 * k)
        rows.append({"vehicle": name, "date": t.date().isoformat(), "log_hash": f"{name}-{k // 2}", "time": t,
                     "event_index": k % 2, "kind": "tip_in", "included": True, "time_is_absolute": True,
                     "measured_gap_open_time_s": (gap_ms + rng.normal(0, 0.5)) / 1e3,
                     "measured_rise_height_rpm": rise_rpm + rng.normal(0, 5),
                     "measured_fluctuation_rpm": ripple_rpm + rng.normal(0, 10)})
    return rows


@pytest.fixture()
def store(tmp_path: Path) -> Path:
    root = tmp_path / "events"
    specs = {"ev-01": (18.0, 250.0, 420.0), "ev-02": (18.5, 255.0, 430.0), "ev-03": (17.5, 245.0, 410.0),
             "ev-04": (18.2, 250.0, 425.0), "ev-05": (30.0, 330.0, 600.0)}  # ev-05: a worn driveline
    for seed, (name, spec) in enumerate(specs.items()):
        rows = _vehicle_rows(name, *spec, seed=seed)
        for h in sorted({r["log_hash"] for r in rows}):
            write_rows(root, [r for r in rows if r["log_hash"] == h], source="batch", log_hash=h)
    return root


def test_outlier_vehicle_is_flagged_with_its_estimates(store: Path, tmp_path: Path) -> None:
    report = fleet_report(store)
    by = {v["vehicle"]: v for v in report["vehicles"]}
    assert list(by) == ["ev-01", "ev-02", "ev-03", "ev-04", "ev-05"] and report["flagged"] == ["ev-05"]
    assert len(by["ev-05"]["flags"]) == 3 and "above the fleet band" in by["ev-05"]["flags"][0]
    frame = read_events(store, vehicle="ev-01")
    gap = frame["measured_gap_open_time_s"].to_numpy() * 1e3
    lash = np.degrees(0.5 * frame["measured_rise_height_rpm"].to_numpy() * math.pi / 30 * gap / 1e3)
    v1 = by["ev-01"]
    assert v1["gap_open_time_ms"]["median"] == pytest.approx(np.median(gap))
    assert v1["total_lash_deg"]["median"] == pytest.approx(np.median(lash))
    assert v1["total_lash_deg"]["median"] == pytest.approx(13.5, abs=0.5)  # 1/2 * 250 rpm * 18 ms, in degrees
    for q in ("gap_open_time_ms", "total_lash_deg", "ripple_rpm"):
        iv = v1[q]
        assert iv["lo"] <= iv["median"] <= iv["hi"] and iv["lo"] < iv["hi"]
    assert (v1["logs"], v1["events"]) == (10, 20)
    assert [w["week"] for w in v1["weekly_ripple_rpm"]] == ["2025-05-05", "2025-05-12"]
    assert [w["events"] for w in v1["weekly_ripple_rpm"]] == [14, 6]
    band = report["bands"]["gap_open_time_ms"]
    assert band["lo"] < 18.0 < band["hi"] < 30.0
    png = report_png(report, tmp_path / "fleet.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # over time: one point per log, oldest first, each the median of that log's events with its interval
    logs = v1["per_log"]
    assert len(logs) == 10 and sum(p["events"] for p in logs) == 20
    assert [p["time"] for p in logs] == sorted(p["time"] for p in logs)
    for p in logs:
        rows = frame[frame["log_hash"] == p["log_hash"]]
        assert p["ripple_rpm"]["median"] == pytest.approx(np.median(rows["measured_fluctuation_rpm"]))
        assert p["ripple_rpm"]["lo"] <= p["ripple_rpm"]["median"] <= p["ripple_rpm"]["hi"]
        assert p["time"] == rows["time"].min().isoformat()


def test_logs_that_do_not_track_are_left_out_of_the_figures_and_counted(store: Path,
                                                                          capsys: pytest.CaptureFixture[str]) -> None:
    """Three logs of ev-01 whose simulation did not track read a 2000 rpm ripple: by default they are not in
    its figures (which then equal the store without them), the report says how many were left out, and
    ``include_poor`` (``--include-poor-tracking``) takes them in."""
    from app.cli import main

    clean = fleet_report(store)
    start = datetime(2025, 5, 6, 8, tzinfo=UTC)
    for k in range(3):
        t = start + timedelta(hours=k)
        rows = [{"vehicle": "ev-01", "date": t.date().isoformat(), "log_hash": f"poor-{k}", "time": t,
                 "event_index": i, "kind": "tip_in", "included": True, "time_is_absolute": True,
                 "measured_gap_open_time_s": 0.05, "measured_rise_height_rpm": 900.0,
                 "measured_fluctuation_rpm": 2000.0, "log_tracking": "poor", "tracking": "poor"} for i in range(4)]
        write_rows(store, rows, source="batch", log_hash=f"poor-{k}")
    report = fleet_report(store)
    assert report["poor_tracking"] == {"events": 12, "logs": 3, "included": False}
    by, before = {v["vehicle"]: v for v in report["vehicles"]}, {v["vehicle"]: v for v in clean["vehicles"]}
    assert by["ev-01"]["events_poor_tracking"] == 12 and by["ev-02"]["events_poor_tracking"] == 0
    for q in ("gap_open_time_ms", "total_lash_deg", "ripple_rpm"):
        assert by["ev-01"][q] == before["ev-01"][q]
    assert by["ev-01"]["weekly_ripple_rpm"] == before["ev-01"]["weekly_ripple_rpm"]
    assert report["flagged"] == clean["flagged"] == ["ev-05"]
    kept = fleet_report(store, include_poor=True)
    v1 = {v["vehicle"]: v for v in kept["vehicles"]}["ev-01"]
    assert kept["poor_tracking"]["included"] is True and v1["events"] == 32
    assert v1["ripple_rpm"]["median"] > by["ev-01"]["ripple_rpm"]["median"]
    assert [w["events"] for w in v1["weekly_ripple_rpm"]] == [26, 6]
    assert main(["fleet", str(store), "--plot", str(store.parent / "f.png")]) == 0
    out = capsys.readouterr().out
    assert ("12 events from 3 logs whose simulation does not track the measurement left out "
            "(--include-poor-tracking includes them)") in out


def test_hook_writes_service_rows_only_when_enabled(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                    fleet_logs: dict[str, Path]) -> None:
    from app.fleet.hook import ENV, after_analysis
    from app.log_source import content_hash
    from app.payload import result_payload
    from app.pipeline import AnalysisOptions, VehicleInputs, run_analysis
    from sim import load_vehicle
    from tests.fleet.conftest import DBC, MAP

    inputs = VehicleInputs(load_vehicle("paper"), DBC, MAP)
    opts = AnalysisOptions(whole_log=False)
    monkeypatch.delenv(ENV, raising=False)
    result = run_analysis(fleet_logs["log2"], inputs, opts)
    doc, _ = result_payload(result)
    after_analysis(fleet_logs["log2"], inputs, doc)
    assert not (tmp_path / "events").exists()
    monkeypatch.setenv(ENV, str(tmp_path / "events"))
    assert run_analysis(fleet_logs["log2"], inputs, opts).events == result.events
    assert not (tmp_path / "events").exists()  # the analysis itself has no side effects; its caller runs the hook
    after_analysis(fleet_logs["log2"], inputs, doc)
    frame = read_events(tmp_path / "events")
    assert len(frame) == len(result.events) and set(frame["source"]) == {"service"}
    assert set(frame["log_hash"]) == {content_hash(fleet_logs["log2"])} and set(frame["vehicle"]) == {"paper"}
    measured = {er.event.index: er.comparison.measured.fluctuation_rpm for er in result.event_results
                if er.comparison is not None}
    got = dict(zip(frame["event_index"], frame["measured_fluctuation_rpm"], strict=True))
    assert measured and all(got[i] == pytest.approx(v) for i, v in measured.items())
    monkeypatch.setenv(ENV, str(tmp_path / "stored"))  # the hash an upload stored is used as given, not recomputed
    after_analysis(fleet_logs["log2"], inputs, doc, log_hash="ab" * 32)
    assert set(read_events(tmp_path / "stored")["log_hash"]) == {"ab" * 32}
    monkeypatch.setenv(ENV, str(fleet_logs["log2"]))  # a file, not a folder: logged, the caller goes on
    after_analysis(fleet_logs["log2"], inputs, doc)


def test_a_vehicle_is_red_on_a_panel_only_outside_that_panels_band(store: Path) -> None:
    """ev-06 has an ordinary lash but a large ripple: flagged, yet inside the lash band drawn behind it."""
    from app.fleet.report import point_colour

    rows = _vehicle_rows("ev-06", 18.1, 251.0, 700.0, seed=9)
    for h in sorted({r["log_hash"] for r in rows}):
        write_rows(store, [r for r in rows if r["log_hash"] == h], source="batch", log_hash=h)
    report = fleet_report(store)
    by = {v["vehicle"]: v for v in report["vehicles"]}
    assert by["ev-06"]["outside"] == ["ripple_rpm"] and by["ev-06"]["flags"]
    band = report["bands"]["total_lash_deg"]
    for v in report["vehicles"]:
        inside = band["lo"] <= v["total_lash_deg"]["median"] <= band["hi"]
        assert (point_colour(v, "total_lash_deg") == "tab:red") == (not inside), v["vehicle"]
    assert point_colour(by["ev-06"], "total_lash_deg") == "tab:orange"
    assert point_colour(by["ev-06"], "ripple_rpm") == "tab:red"
    assert point_colour(by["ev-01"], "total_lash_deg") == "tab:blue"
    assert point_colour(by["ev-05"], "total_lash_deg") == "tab:red"


def test_service_rows_carry_the_registered_vehicle_name(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                        fleet_logs: dict[str, Path]) -> None:
    from app.fleet.hook import ENV, after_analysis
    from app.payload import result_payload
    from app.pipeline import AnalysisOptions, VehicleInputs, run_analysis
    from sim import load_vehicle
    from tests.fleet.conftest import DBC, MAP

    monkeypatch.setenv(ENV, str(tmp_path / "events"))
    inputs = VehicleInputs(load_vehicle("paper"), DBC, MAP, "my-car")
    after_analysis(fleet_logs["log2"], inputs,
                   result_payload(run_analysis(fleet_logs["log2"], inputs, AnalysisOptions(whole_log=False)))[0])
    frame = read_events(tmp_path / "events")
    assert set(frame["vehicle"]) == {"my-car"} and set(frame["driveline"]) == {"paper"}


def test_cli_analyze_writes_service_rows_when_a_store_is_named(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                                fleet_logs: dict[str, Path]) -> None:
    from app.cli import main
    from app.fleet.hook import ENV
    from app.log_source import content_hash

    monkeypatch.setenv(ENV, str(tmp_path / "events"))
    assert main(["analyze", str(fleet_logs["log2"]), "--vehicle", "paper", "--no-whole-log",
                 "--out", str(tmp_path / "a.json")]) == 0
    doc = json.loads((tmp_path / "a.json").read_text())
    frame = read_events(tmp_path / "events")
    assert len(frame) == len(doc["events"]) > 0 and set(frame["source"]) == {"service"}
    assert set(frame["log_hash"]) == {content_hash(fleet_logs["log2"])}
