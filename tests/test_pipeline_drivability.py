"""Drivability criteria through the pipeline: the demo drive's accelerometer, measured against simulated,
the speed-derived fallback, and the criteria in the payload, the CSV table and the event-store rows."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from app.analysis.drivability import CRITERIA_NAMES, DrivabilityParams
from app.api.tables import DRIVABILITY_COLUMNS, metrics_csv
from app.demo.scenario import Scenario, measured_channels
from app.fleet.rows import event_rows
from app.payload import result_payload
from app.pipeline import AnalysisOptions, AnalysisResult, analyze_signals
from app.signals import Interp, Signal, SignalSet
from app.storage.results import json_safe
from sim import load_vehicle

SCENARIO = Scenario(duration_s=24.0, truth_changes={}, brake_cycle=-1)


def _signals(sc: Scenario, drop: tuple[str, ...] = ()) -> SignalSet:
    ss = SignalSet()
    for name, ch in measured_channels(load_vehicle("paper"), sc).items():
        if name not in drop:
            interp = Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR
            ss.add(Signal.from_samples(name, ch.t, ch.values, interp=interp))
    return ss


@pytest.fixture(scope="module")
def with_accelerometer() -> AnalysisResult:
    return analyze_signals(_signals(SCENARIO), load_vehicle("paper"), AnalysisOptions())


def test_model_equal_to_truth_gives_matching_criteria(with_accelerometer: AnalysisResult) -> None:
    res = with_accelerometer
    assert res.acceleration is not None and res.acceleration.kind == "accelerometer"
    assert res.acceleration.check is not None and res.acceleration.check.verdict == "ok"
    assert res.acceleration.check.offset_ms2 == pytest.approx(SCENARIO.accel_offset_ms2, abs=0.03)
    feels = [er.feel for er in res.event_results if er.feel is not None]
    assert len(feels) >= 6
    for f in feels:
        m, s = f.measured, f.simulated
        assert m.shuffle_freq_hz == pytest.approx(s.shuffle_freq_hz, rel=0.05)
        assert m.shuffle_pp_ms2 == pytest.approx(s.shuffle_pp_ms2, rel=0.2, abs=0.1)
        assert m.vdv_ms175 == pytest.approx(s.vdv_ms175, rel=0.05)
        assert m.settled_accel_ms2 == pytest.approx(s.settled_accel_ms2, abs=0.1)
        assert 0.02 < m.response_delay_s < 0.3  # the pedal leads the torque by 50 ms, the rise follows it
    assert "drivability" in res.timings_s


def test_without_an_accelerometer_the_road_speed_is_differentiated() -> None:
    res = analyze_signals(_signals(SCENARIO, drop=("accel_long_ms2",)), load_vehicle("paper"), AnalysisOptions())
    assert res.acceleration is not None and res.acceleration.kind == "vehicle_speed"
    assert 10.0 < res.acceleration.bandwidth_hz < 15.0
    feels = [er.feel for er in res.event_results if er.feel is not None]
    assert feels and all(f.source == "vehicle_speed" for f in feels)
    for f in feels:  # the ~7.6 Hz shuffle is above half the differentiator's bandwidth: unresolved, not a number
        assert f.measured.resolution["clunk_ms2"].startswith("unresolved")
        if math.isnan(f.measured.shuffle_pp_ms2):
            assert f.measured.resolution["shuffle_pp_ms2"].startswith("unresolved")
        assert math.isfinite(f.measured.vdv_ms175) and math.isfinite(f.measured.settled_accel_ms2)


def test_criteria_can_be_switched_off() -> None:
    opts = AnalysisOptions(drivability=DrivabilityParams(enabled=False))
    res = analyze_signals(_signals(replace(SCENARIO, duration_s=10.0)), load_vehicle("paper"), opts)
    assert res.acceleration is None and all(er.feel is None for er in res.event_results)
    assert "drivability" not in res.timings_s
    doc, _ = result_payload(res)
    assert doc["summary"]["drivability"] == {} and doc["acceleration"] is None


def test_options_round_trip_through_a_dict() -> None:
    opts = AnalysisOptions(drivability=DrivabilityParams(lowpass_hz=15.0, clunk_band_hz=(25.0, 150.0)))
    back = AnalysisOptions.from_dict(opts.to_dict())
    assert back.drivability == opts.drivability
    from app.errors import InputError

    with pytest.raises(InputError, match="drivability"):
        AnalysisOptions.from_dict({"drivability": {"clunk_band_hz": [100.0, 20.0]}})


def test_payload_csv_and_event_store_rows_carry_the_criteria(with_accelerometer: AnalysisResult) -> None:
    doc, _ = result_payload(with_accelerometer)
    doc = dict(json_safe(doc))
    assert doc["acceleration"]["kind"] == "accelerometer"
    summ = doc["summary"]["drivability"]
    assert set(summ) == set(CRITERIA_NAMES) and summ["shuffle_pp_ms2"]["events"] >= 6
    settled = summ["settled_accel_ms2"]  # forward after a tip-in, backward after a tip-out: medians per kind only
    assert settled["measured_median"] is None and settled["simulated_median"] is None
    assert settled["tip_in"]["measured_median"] > 0.5 and settled["tip_out"]["measured_median"] < -0.5
    assert settled["tip_in"]["events"] + settled["tip_out"]["events"] == settled["events"] >= 6
    assert summ["kick_ms2"]["measured_median"] > 0 and summ["kick_ms2"]["tip_in"]["events"] >= 3
    row = next(m for m in doc["metrics"] if m["drivability"])
    assert set(row["drivability"]["measured"]) >= set(CRITERIA_NAMES)
    text = metrics_csv(doc["metrics"])
    header = text.splitlines()[0].split(",")
    assert set(DRIVABILITY_COLUMNS) <= set(header) and "accel_source" in header
    first = dict(zip(header, text.splitlines()[1].split(","), strict=True))
    assert float(first["accel_shuffle_pp_ms2_measured"]) == pytest.approx(
        doc["metrics"][0]["drivability"]["measured"]["shuffle_pp_ms2"], rel=1e-9)
    rows = event_rows(doc, vehicle="paper", log_hash="h", log_name="demo.blf", source="batch", driveline="paper")
    analysed = [r for r in rows if np.isfinite(r["measured_accel_shuffle_pp_ms2"])]
    assert len(analysed) == summ["shuffle_pp_ms2"]["events"]
    assert all(r["accel_source"] == "accelerometer" for r in analysed)


def test_an_inverted_accelerometer_is_a_finding_and_the_road_speed_stands_in() -> None:
    ss = _signals(replace(SCENARIO, duration_s=12.0))
    acc = ss["accel_long_ms2"]
    ss.add(Signal("accel_long_ms2", acc.t, -acc.values, acc.unit))
    res = analyze_signals(ss, load_vehicle("paper"), AnalysisOptions())
    assert "accel_sign" in [f.code for f in res.findings]
    assert res.acceleration is not None and res.acceleration.kind == "vehicle_speed"
    assert res.acceleration.check is not None and res.acceleration.check.verdict == "sign"
    doc, _ = result_payload(res)
    assert doc["acceleration"]["note"] == "accelerometer rejected (sign)"


def test_no_accelerometer_and_no_road_speed_leaves_the_criteria_out_with_a_note() -> None:
    road = ("accel_long_ms2", "vehicle_speed_kmh", *(f"wheel_speed_{w}_rpm" for w in ("fl", "fr", "rl", "rr")))
    res = analyze_signals(_signals(replace(SCENARIO, duration_s=10.0), drop=road), load_vehicle("paper"),
                          AnalysisOptions())
    assert res.acceleration is None and all(er.feel is None for er in res.event_results)
    assert any(n.startswith("no acceleration") for n in res.notes)
    assert any(er.comparison is not None for er in res.event_results)  # the speed metrics are there as before


def test_a_vehicle_with_a_body_pitch_reports_the_seat_rail_beside_and_compares_it_on_request() -> None:
    signals = _signals(replace(SCENARIO, duration_s=12.0))
    pitched = load_vehicle("paper").with_changes({"body_pitch.enabled": True})
    body = analyze_signals(signals, pitched, AnalysisOptions())
    seat = analyze_signals(signals, pitched, AnalysisOptions(drivability=DrivabilityParams(compare_with="seat_rail")))
    pairs = [(b.feel, s.feel) for b, s in zip(body.event_results, seat.event_results, strict=True)
             if b.feel is not None and s.feel is not None]
    assert len(pairs) >= 2  # a tip-in and a tip-out
    for fb, fs in pairs:
        assert fb.simulated_at == "body" and fb.simulated_seat is not None
        assert fs.simulated_at == "seat_rail" and fs.simulated == fs.simulated_seat == fb.simulated_seat
        assert fs.measured == fb.measured  # the measurement does not depend on which simulated side is compared
        assert fs.difference["shuffle_pp_ms2"] == pytest.approx(
            fs.simulated.shuffle_pp_ms2 - fs.measured.shuffle_pp_ms2, rel=1e-12)
        # the seat rail below the centre of gravity swings more than the body, at the same frequency
        assert fb.simulated_seat.shuffle_pp_ms2 > fb.simulated.shuffle_pp_ms2
        assert fb.simulated_seat.shuffle_freq_hz == pytest.approx(fb.simulated.shuffle_freq_hz, rel=0.02)
    doc = dict(json_safe(result_payload(body)[0]))
    row = next(m for m in doc["metrics"] if m["drivability"])
    assert row["drivability"]["simulated_at"] == "body"
    assert set(row["drivability"]["simulated_seat"]) >= set(CRITERIA_NAMES)
    plain = analyze_signals(signals, load_vehicle("paper"), AnalysisOptions(
        drivability=DrivabilityParams(compare_with="seat_rail")))  # no [body_pitch]: the body, said so
    feel = next(er.feel for er in plain.event_results if er.feel is not None)
    assert feel.simulated_at == "body" and feel.simulated_seat is None
    assert "simulated_seat" not in feel.to_dict()
    with pytest.raises(ValueError, match="compare_with"):
        DrivabilityParams(compare_with="head_rest")
