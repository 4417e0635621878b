"""Tracking verdict: is the measured-versus-simulated comparison valid? Drives simulated with the
paper preset (good), with a very different vehicle (half-shaft stiffness x0.2) and with a wheel
spinning up (whole-log drift), analysed against the paper preset; and what the CLI says."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from app.analysis.tracking import TrackingParams
from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Scenario, measured_channels
from app.errors import InputError
from app.payload import result_payload
from app.pipeline import AnalysisOptions, AnalysisResult, analyze_signals
from app.settings import default_dbc_dir
from app.signals import Interp, Signal, SignalSet
from sim import load_vehicle

DBC = default_dbc_dir()
PAPER = load_vehicle("paper")


def _analyse(sc: Scenario, spin: Callable[[np.ndarray], np.ndarray] | None = None,
             wheels: bool = True) -> AnalysisResult:
    ss = SignalSet()
    for name, ch in measured_channels(PAPER, sc).items():
        if name.startswith("wheel_speed") and not wheels:
            continue
        v = ch.values + (spin(ch.t) if spin is not None and name == "motor_speed_rpm" else 0.0)
        interp = Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR
        ss.add(Signal.from_samples(name, ch.t, v, interp=interp))
    return analyze_signals(ss, PAPER, AnalysisOptions())


def test_paper_drive_against_the_paper_preset_tracks() -> None:
    res = _analyse(Scenario(duration_s=30.0))
    assert res.tracking.verdict == "good" and res.tracking.reasons == []
    judged = [er.tracking for er in res.event_results if er.tracking is not None]
    assert len(judged) >= 8 and all(v.verdict == "good" for v in judged)
    assert res.offset.applied and res.offset.correlation > 0.9
    doc, _ = result_payload(res)
    assert doc["summary"]["tracking"] == {"verdict": "good", "reasons": []}
    assert doc["summary"]["offset_applied"] is True
    assert all(m["tracking"]["verdict"] == "good" for m in doc["metrics"])


def test_a_much_softer_halfshaft_does_not_track_and_says_why() -> None:
    res = _analyse(Scenario(duration_s=30.0, truth_changes={"halfshaft.stiffness": 0.2}))
    assert res.tracking.verdict == "poor"
    first, second = res.tracking.reasons
    assert first == ("10 of 10 analysed events do not track (NRMSE above 0.2 in 0, shuffle frequency off by more "
                     "than 25 % in 10)")
    assert second.startswith("torque-to-speed offset not applied: its correlation 0.28 is below 0.5")
    # the offset is not applied, and the notes say so
    assert not res.offset.applied
    assert any(n.startswith("torque-to-speed offset 50.0 ms not applied") for n in res.notes)
    poor = [er for er in res.event_results if er.comparison is not None]
    for er in poor:
        assert er.tracking is not None and er.tracking.verdict == "poor"
        c = er.comparison
        assert c is not None
        assert 3.3 < c.measured.shuffle_freq_hz < 4.5 and 7.2 < c.simulated.shuffle_freq_hz < 8.0  # still returned
        assert any(r.startswith(f"shuffle frequency {c.simulated.shuffle_freq_hz:.1f} Hz simulated vs "
                                f"{c.measured.shuffle_freq_hz:.1f} Hz measured") for r in er.tracking.reasons)


def test_wheelspin_drift_makes_the_log_poor_and_excludes_the_slipping_events() -> None:
    res = _analyse(Scenario(duration_s=30.0), spin=lambda t: 3000.0 * np.clip((t - 12.0) / 3.0, 0.0, 1.0))
    assert res.tracking.verdict == "poor"
    (reason,) = res.tracking.reasons
    assert reason.startswith("whole-log simulation drifts -2999 rpm from the measured speed")
    slipping = [e for e in res.events if e.exclusion and e.exclusion.startswith("wheel slip")]
    assert [e.index for e in slipping] == [4, 5, 6, 7, 8, 9]
    # without wheel or vehicle speed channels the slip is not seen, but the drift still is
    no_ref = _analyse(Scenario(duration_s=30.0), spin=lambda t: 3000.0 * np.clip((t - 12.0) / 3.0, 0.0, 1.0),
                      wheels=False)
    assert any(r.startswith("whole-log simulation drifts") for r in no_ref.tracking.reasons)


def test_tracking_thresholds_come_from_the_request_body() -> None:
    opts = AnalysisOptions.from_dict({"tracking": {"max_nrmse": 0.1}, "events": {"min_dwell_s": 0.2}})
    assert opts.tracking == TrackingParams(max_nrmse=0.1) and opts.events.min_dwell_s == 0.2
    with pytest.raises(InputError, match=r"TrackingParams\.min_offset_correlation"):
        AnalysisOptions.from_dict({"tracking": {"min_offset_correlation": 2.0}})


@pytest.fixture(scope="module")
def soft_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("track") / "soft.blf"
    build_demo_log(path, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml",
                   Scenario(duration_s=20.0, truth_changes={"halfshaft.stiffness": 0.2}))
    return path


def test_cli_warns_above_the_medians_and_takes_event_thresholds(soft_log: Path,
                                                                capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["analyze", str(soft_log), "--vehicle", "paper", "--no-whole-log"]) == 0
    out = capsys.readouterr().out
    warn = out.index("WARNING: the simulation does not track this log")
    assert warn < out.index("metric (median over events)")
    assert "torque-to-speed offset not applied (estimate" in out.splitlines()[0]
    assert "tracking poor" in out.splitlines()[0]
    assert main(["analyze", str(soft_log), "--vehicle", "paper", "--no-whole-log", "--json", "--min-dwell", "3"]) == 0
    assert json.loads(capsys.readouterr().out)["summary"]["events"] == 0  # no side holds 3 s


@pytest.mark.parametrize("command", ["analyze", "diagnose"])
def test_bad_event_threshold_is_a_one_line_error_naming_the_option(command: str, soft_log: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    assert main([command, str(soft_log), "--vehicle", "paper", "--max-ramp-reversal", "2"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [") and "--max-ramp-reversal = 2.0: must be in [0, 1]" in err
    assert len(err.strip().splitlines()) == 1


def test_a_vehicle_whose_ratio_does_not_fit_the_log_is_named_and_not_mistaken_for_slip() -> None:
    ss = SignalSet()
    for name, ch in measured_channels(PAPER, Scenario(duration_s=20.0)).items():
        road = name.startswith("wheel_speed") or name == "vehicle_speed_kmh"
        ss.add(Signal.from_samples(name, ch.t, ch.values * (2.0 if road else 1.0),
                                   interp=Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR))
    res = analyze_signals(ss, PAPER, AnalysisOptions())
    first = res.tracking.reasons[0]
    assert first.startswith("the vehicle does not fit the log: the motor turns 0.50x the speed the file's "
                            "ratio 11.2648")
    assert not any(e.exclusion and e.exclusion.startswith("wheel slip") for e in res.events)


def test_the_command_line_defaults_are_the_event_defaults() -> None:
    from app.analysis.events import EventParams
    from app.cli.vehicle_args import EVENT_OPTIONS

    defaults = EventParams()
    assert {name: default for _, name, _, default, _ in EVENT_OPTIONS} == {
        name: getattr(defaults, name) for _, name, _, _, _ in EVENT_OPTIONS}


def test_command_line_thresholds_go_over_the_command_s_own_defaults() -> None:
    """``diagnose`` keeps its 0.3 s post-window under thresholds given on the command line; ``analyze`` keeps 0.6 s."""
    import argparse

    from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
    from app.analysis.events import EventParams
    from app.cli.vehicle_args import add_log_and_vehicle, event_params

    p = argparse.ArgumentParser()
    add_log_and_vehicle(p)
    args = p.parse_args(["drive.blf", "--vehicle", "paper", "--min-dwell", "0.1"])
    diag = event_params(args, DIAGNOSIS_EVENTS)
    assert diag.min_post_s == 0.3 and diag.min_dwell_s == 0.1
    plain = event_params(args)
    assert plain.min_post_s == EventParams().min_post_s == 0.6 and plain.min_dwell_s == 0.1
