"""The pipeline from decoded signals on: events, per-event simulation, offset, metrics, payload."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.demo.scenario import Scenario, measured_channels
from app.errors import InputError, MissingSignalError
from app.payload import result_payload
from app.pipeline import AnalysisOptions, analyze_signals
from app.signals import Interp, Signal, SignalSet
from app.storage.results import ResultFiles, write_result
from sim import load_vehicle


def _signals(sc: Scenario) -> SignalSet:
    ss = SignalSet()
    for name, ch in measured_channels(load_vehicle("paper"), sc).items():
        interp = Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR
        ss.add(Signal.from_samples(name, ch.t, ch.values, interp=interp))
    return ss


@pytest.fixture(scope="module")
def paper() -> object:
    return load_vehicle("paper")


def test_model_equal_to_truth_gives_matching_metrics_and_the_offset(paper: object) -> None:
    sc = Scenario(duration_s=30.0, truth_changes={}, speed_lag_s=0.012, speed_noise_rpm=0.5, brake_cycle=-1)
    res = analyze_signals(_signals(sc), paper, AnalysisOptions())  # type: ignore[arg-type]
    assert res.offset.lag_s == pytest.approx(0.012, abs=0.002)
    done = [er for er in res.event_results if er.comparison is not None]
    assert len(done) >= 8
    for er in done:
        c = er.comparison
        assert c is not None
        assert c.error.nrmse < 0.05
        fm, fs = c.measured.fluctuation_rpm, c.simulated.fluctuation_rpm
        if np.isfinite(fm) and fm > 100:
            assert fs == pytest.approx(fm, rel=0.12)
        assert c.measured.shuffle_freq_hz == pytest.approx(c.simulated.shuffle_freq_hz, rel=0.08)
        assert 0.005 < er.sim_gap_open_time_s < 0.06
    assert res.whole is not None and res.whole_error is not None and res.whole_error.nrmse < 0.05


def test_smaller_true_halfshaft_gap_shows_as_larger_simulated_ripple(paper: object, tmp_path: Path) -> None:
    sc = Scenario(duration_s=30.0, brake_cycle=2)
    progress: list[tuple[str, float]] = []
    res = analyze_signals(_signals(sc), paper, AnalysisOptions(), lambda f, s: progress.append((s, f)))
    assert any(e.exclusion and e.exclusion.startswith("braking") for e in res.events)
    diffs = [er.comparison.difference["fluctuation_rpm"] for er in res.event_results
             if er.comparison is not None and np.isfinite(er.comparison.difference["fluctuation_rpm"])]
    assert np.median(diffs) > 0
    fracs = [f for _, f in progress]
    assert fracs == sorted(fracs) and fracs[-1] == 1.0

    doc, arrays = result_payload(res)
    write_result(tmp_path / "r", doc, arrays)
    files = ResultFiles(tmp_path / "r")
    assert files.doc["summary"]["with_metrics"] == len(diffs) or files.doc["summary"]["with_metrics"] >= len(diffs)
    k = files.doc["metrics"][0]["event_index"]
    a, b = files.doc["event_rows"][str(k)]
    assert files.array("ev_t")[a:b].size == b - a > 100
    assert files.array("whole_t").size == files.doc["whole"]["points"]


def test_missing_channels_and_bad_options_are_typed_errors(paper: object) -> None:
    ss = SignalSet()
    ss.add(Signal.from_samples("motor_torque_nm", [0.0, 1.0], [1.0, 2.0]))
    with pytest.raises(MissingSignalError, match="motor_speed_rpm"):
        analyze_signals(ss, paper)  # type: ignore[arg-type]
    with pytest.raises(InputError, match="model"):
        AnalysisOptions.from_dict({"model": "quantum"})
    with pytest.raises(InputError, match="nope"):
        AnalysisOptions.from_dict({"nope": 1})
    opts = AnalysisOptions.from_dict({"events": {"min_step_nm": 10.0, "step_before_s": [0.2, 0.05]}})
    assert opts.events.min_step_nm == 10.0 and opts.events.step_before_s == (0.2, 0.05)
    assert AnalysisOptions.from_dict(opts.to_dict()) == opts


@pytest.mark.parametrize(("span_s", "period_s", "expected"), [
    (600.0, 0.01, 0.01),  # 10 min at 100 Hz: the speed signal's own period
    (600.0, 0.0005, 1e-3),  # faster than 1 kHz: clipped to 1 ms
    (1800.0, 0.001, 1.8e-3),  # 30 min at 1 kHz: coarsened to stay within WHOLE_LOG_MAX_ROWS
    (36_000.0, 0.01, 0.036),  # 10 h at 100 Hz: coarsened
])
def test_whole_log_output_step_stays_within_the_row_budget(span_s: float, period_s: float, expected: float) -> None:
    from app.pipeline import WHOLE_LOG_MAX_ROWS, whole_log_output_dt

    dt = whole_log_output_dt(span_s, period_s)
    assert dt == pytest.approx(expected)
    assert span_s / dt <= WHOLE_LOG_MAX_ROWS * (1 + 1e-9)
