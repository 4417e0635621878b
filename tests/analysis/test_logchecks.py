"""Real logs as they come: an inverted torque channel, values from the wrong DBC, wheel speeds a VCU
computed from the motor speed, and a wheel spinning up without any wheel speed in the log. Each defect is
put into the scripted demo drive (paper preset), on signals and through a real BLF file."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from app.analysis.logchecks import CheckParams, Limits, check_log
from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Channel, Scenario, measured_channels
from app.errors import ImplausibleSignalError
from app.payload import result_payload
from app.pipeline import AnalysisOptions, AnalysisResult, analyze_signals
from app.settings import default_dbc_dir
from app.signals import Interp, Signal, SignalSet
from sim import load_vehicle
from tests.conftest import edited_map

PAPER = load_vehicle("paper")
DBC = default_dbc_dir()
Edit = Callable[[np.ndarray, np.ndarray], np.ndarray]
ROAD = ("wheel_speed_", "vehicle_speed_kmh")


@pytest.fixture(scope="module")
def channels() -> dict[str, Channel]:
    return measured_channels(PAPER, Scenario(duration_s=20.0))


def _signals(channels: dict[str, Channel], edits: dict[str, Edit] | None = None, road: bool = True) -> SignalSet:
    ss = SignalSet()
    for name, ch in channels.items():
        if not road and name.startswith(ROAD):
            continue
        v = (edits or {}).get(name, lambda t, v: v)(ch.t, ch.values)
        interp = Interp.PREVIOUS if name.startswith("brake") else Interp.LINEAR
        ss.add(Signal.from_samples(name, ch.t, v, interp=interp))
    return ss


def _analyse(ss: SignalSet, **checks: object) -> AnalysisResult:
    return analyze_signals(ss, PAPER, AnalysisOptions(whole_log=False, checks=CheckParams(**checks)))  # type: ignore[arg-type]


def _kinds(res: AnalysisResult) -> list[tuple[str, str | None]]:
    return [(e.kind.value, e.exclusion) for e in res.events]


def test_the_clean_drive_has_no_findings(channels: dict[str, Channel]) -> None:
    checks = check_log(_signals(channels), Limits.for_vehicle(PAPER))
    assert checks.findings == [] and checks.computed == frozenset()
    assert checks.sign_correlation == pytest.approx(0.70, abs=0.01)


def test_an_inverted_torque_is_named_and_analysed_with_the_sign_corrected(channels: dict[str, Channel]) -> None:
    clean = _analyse(_signals(channels))
    res = _analyse(_signals(channels, {"motor_torque_nm": lambda t, v: -v}))
    (finding,) = res.findings
    assert finding.code == "torque_sign_inverted" and finding.channel == "motor_torque_nm"
    assert finding.message.startswith("motor_torque_nm is inverted relative to the motor speed: its rank "
                                      "correlation with the motor acceleration is -0.70; analysed with the sign "
                                      "corrected")
    assert _kinds(res) == _kinds(clean) and len(res.events) == 6
    assert res.signals["motor_torque_nm"].values == pytest.approx(clean.signals["motor_torque_nm"].values)
    doc, _ = result_payload(res)
    assert doc["summary"]["findings"] == [finding.to_dict()]
    # asked not to correct it, the analysis says what the events then are
    kept = _analyse(_signals(channels, {"motor_torque_nm": lambda t, v: -v}), fix_torque_sign=False)
    assert kept.findings[0].message.split("; ")[1].startswith("analysed as decoded, so every tip-in reads as a "
                                                              "tip-out")
    assert [k for k, _ in _kinds(kept)] == [{"tip_in": "tip_out", "tip_out": "tip_in"}[k] for k, _ in _kinds(clean)]


def test_the_sign_is_not_judged_while_the_friction_brakes_act(channels: dict[str, Channel]) -> None:
    """Braking decelerates the car whatever the torque: samples near an applied brake do not count. The inverted
    drive braked after 10 s (a line pressure resting at its 10 psi offset, then 200 psi) reads its sign from the
    first 10 s; with the brake switch on throughout, the sign is not judged (no finding) rather than judged from
    the brakes."""
    from app.analysis.logchecks import sign_correlation

    inverted = _signals(channels, {"motor_torque_nm": lambda t, v: -v})
    tq, sp = inverted["motor_torque_nm"], inverted["motor_speed_rpm"]
    first = sign_correlation(tq.window(0.0, 10.0), sp.window(0.0, 10.0), 0.2)
    late = _signals(channels, {"motor_torque_nm": lambda t, v: -v,
                               "brake": lambda t, v: np.where(t > 10.0, 200.0, 10.0)})
    checks = check_log(late, Limits.for_vehicle(PAPER))
    assert checks.sign_correlation == pytest.approx(first, abs=0.03) and first < -0.5
    always = _signals(channels, {"motor_torque_nm": lambda t, v: -v})
    t = always["motor_speed_rpm"].t
    always.add(Signal.from_samples("brake_pressed", t, np.ones(t.size), interp=Interp.PREVIOUS))
    checks = check_log(always, Limits.for_vehicle(PAPER))
    assert np.isnan(checks.sign_correlation) and checks.findings == []


def test_check_thresholds_come_from_the_request_body() -> None:
    from app.errors import InputError

    opts = AnalysisOptions.from_dict({"checks": {"fix_torque_sign": False, "torque_margin": 2.0}})
    assert opts.checks == CheckParams(fix_torque_sign=False, torque_margin=2.0)
    with pytest.raises(InputError, match=r"CheckParams\.min_sign_correlation = 2\.0: must be in \(0, 1\]"):
        AnalysisOptions.from_dict({"checks": {"min_sign_correlation": 2.0}})


def test_a_torque_glitch_is_implausible_and_named_with_value_and_limit(channels: dict[str, Channel]) -> None:
    def glitch(t: np.ndarray, v: np.ndarray) -> np.ndarray:
        return np.where(np.abs(t - 15.0) < 0.025, 3276.7, v)  # a 0x7FFF "not available" decoded as a value

    res = _analyse(_signals(channels, {"motor_torque_nm": glitch}))
    torque, power = res.findings
    assert (torque.code, torque.channel) == ("implausible_signal", "motor_torque_nm")
    assert torque.message.startswith("motor_torque_nm reads +3277 N m at t=14.98 s, beyond 1.5 x the motor's "
                                     "peak torque 917 N m (0.3 % of its samples)")
    assert (power.code, power.channel) == ("implausible_signal", "motor power")
    assert "beyond 1.5 x max_power_kw 240 kW" in power.message
    assert len(res.events) == 6  # a glitch is named, the analysis goes on


def test_speed_from_the_wrong_dbc_version_is_refused_naming_the_likely_cause(channels: dict[str, Channel]) -> None:
    ss = _signals(channels, {"motor_speed_rpm": lambda t, v: 12.0 * v})
    with pytest.raises(ImplausibleSignalError, match=r"^motor_speed_rpm reads \+45592 rpm at t=13.45 s, beyond the "
                       r"motor speed at 250 km/h 23344 rpm \(86.8 % of its samples\): the log was most likely "
                       r"decoded with the wrong DBC version or scaling") as info:
        _analyse(ss)
    assert info.value.code == "implausible_signal" and info.value.status == 422


def _computed(ch: Channel, k: float, step: float) -> Edit:
    """A wheel speed a VCU computes: the motor speed x ``k``, on the wheel channel's own time stamps, quantised."""
    return lambda t, v: np.round(np.interp(t, ch.t, ch.values) * k / step) * step


def test_a_wheel_speed_computed_from_the_motor_speed_is_not_road_truth(channels: dict[str, Channel]) -> None:
    sp = channels["motor_speed_rpm"]
    spin: Edit = lambda t, v: v + 3000.0 * np.clip((t - 8.0) / 0.5, 0.0, 1.0)  # noqa: E731
    spun = {**channels, "motor_speed_rpm": Channel(sp.t, spin(sp.t, sp.values), sp.period_s)}
    only = {k: v for k, v in spun.items() if not k.startswith(ROAD) or k == "wheel_speed_fl_rpm"}
    ss = _signals(only, {"wheel_speed_fl_rpm": _computed(spun["motor_speed_rpm"], 1.0 / PAPER.ratio, 0.1)})
    res = _analyse(ss)
    (finding,) = res.findings
    assert (finding.code, finding.channel) == ("wheel_speed_computed", "wheel_speed_fl_rpm")
    assert finding.message.startswith("wheel_speed_fl_rpm is the motor speed x 0.0887719 within 0.118 % through "
                                      "the shuffle")
    assert 1.0 / PAPER.ratio == pytest.approx(0.0887719, rel=1e-6)
    # the computed channel follows the spin; the spin is still found, from the motor alone
    spinning = [e for e in res.events if e.exclusion and e.exclusion.startswith("wheel spin")]
    assert [e.index for e in spinning] == [2]
    # the measured wheel speeds of the same drive are not taken for computed ones
    assert check_log(_signals(channels), Limits.for_vehicle(PAPER)).computed == frozenset()


def test_wheel_spin_without_wheel_speeds_excludes_the_event_with_the_reason(channels: dict[str, Channel]) -> None:
    clean = _analyse(_signals(channels, road=False))
    assert all(e.included for e in clean.events)  # the shuffle itself is not taken for a spin
    res = _analyse(_signals(channels, {"motor_speed_rpm": lambda t, v: v + 3000.0 * np.clip((t - 8.0) / 0.5, 0, 1)},
                            road=False))
    excluded = [(e.index, e.exclusion) for e in res.events if not e.included]
    assert len(excluded) == 1 and excluded[0][0] == 2
    assert excluded[0][1] == ("wheel spin: the motor gains 6561 rpm/s over 7.99-8.49 s; 93 N m on 1.47 kg m^2 (the "
                              "vehicle at the motor) allows at most 1410 rpm/s (x1.5, with a 1.5 m/s^2 road "
                              "allowance); no wheel speed to compare with")


@pytest.fixture(scope="module")
def demo_blf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("checks") / "drive.blf"
    build_demo_log(path, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml", Scenario(duration_s=12.0))
    return path


def test_cli_warns_about_an_inverted_torque_in_a_real_file(demo_blf: Path, tmp_path: Path,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    smap = edited_map(tmp_path, "motor_torque_nm", "invert = true")
    assert main(["analyze", str(demo_blf), "--vehicle", "paper", "--no-whole-log", "--signal-map", str(smap)]) == 0
    out = capsys.readouterr().out
    assert "WARNING [torque_sign_inverted]: motor_torque_nm is inverted relative to the motor speed" in out
    assert out.index("WARNING [torque_sign_inverted]") < out.index("metric (median over events)")
    assert main(["analyze", str(demo_blf), "--vehicle", "paper", "--no-whole-log", "--signal-map", str(smap),
                 "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert [f["code"] for f in doc["summary"]["findings"]] == ["torque_sign_inverted"]
    assert doc["summary"]["with_metrics"] > 0


def test_cli_refuses_a_speed_scaled_by_the_wrong_factor(demo_blf: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    smap = edited_map(tmp_path, "motor_speed_rpm", "factor = 12.0")
    assert main(["analyze", str(demo_blf), "--vehicle", "paper", "--signal-map", str(smap)]) != 0
    err = capsys.readouterr().err
    assert err.startswith("lashscope: error [implausible_signal]: motor_speed_rpm reads")
    assert "wrong DBC version or scaling" in err and len(err.strip().splitlines()) == 1


def _held(t: np.ndarray) -> np.ndarray:
    """Logger stamps of frames sampled at ``t``: every second a gateway holds the frames of 120 ms and
    writes them back-to-back, 0.1 ms apart, when it lets go."""
    out = t.copy()
    for k in range(int(t[-1]) + 1):
        held = np.flatnonzero((t >= k + 0.3) & (t < k + 0.42))
        out[held] = k + 0.42 + 1e-4 * np.arange(held.size)
    return out


def test_timer_times_recover_the_sampling_times_from_a_wrapping_counter() -> None:
    """An 8-bit counter stepping every 10 ms (wraps every 2.56 s, starts at 17) on an ECU clock 50 ppm fast
    puts frames a gateway held for up to 120 ms back within the sampling jitter."""
    from app.analysis.sampling import timer_times, unwrap_timer

    rng = np.random.default_rng(5)
    grid = 0.01 * np.arange(2000)
    t_true = grid + rng.uniform(-3e-4, 3e-4, grid.size)
    counter = np.mod(np.arange(2000) + 17, 256) * 0.01 * (1 + 50e-6)  # what the payload carries
    assert np.all(np.diff(unwrap_timer(counter)) > 0)
    logged = _held(t_true)
    assert float(np.max(np.abs(logged - t_true))) == pytest.approx(0.12, abs=0.011)
    fixed = timer_times(logged, counter)
    assert float(np.max(np.abs(fixed - t_true))) < 6e-4


def _with_time_base(tmp_path: Path) -> Path:
    text = (DBC / "lashscope_ev.map.toml").read_text(encoding="utf-8")
    out = tmp_path / "timed.map.toml"
    out.write_text(text + '\n[channels.time_base]\nmessage = "MCU_Speed"\nsignal = "MCU_SpeedAlive"\nunit = "s"\n'
                   'factor = 0.01\n', encoding="utf-8")
    return out


def test_a_time_base_channel_re_times_speed_stamps_a_gateway_held(tmp_path: Path) -> None:
    """A BLF whose motor speed frames were held by a gateway (120 ms every second): the speed message's alive
    counter, mapped as the time base, puts them back within a millisecond of when they were sampled."""
    from app.demo.build import encode_blf
    from app.pipeline import VehicleInputs, run_analysis, signal_routes

    channels = measured_channels(PAPER, Scenario(duration_s=12.0))
    sp = channels["motor_speed_rpm"]
    held = {**channels, "motor_speed_rpm": Channel(_held(sp.t), sp.values, sp.period_s)}
    loaded, routes = signal_routes(DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml")
    log = tmp_path / "held.blf"
    encode_blf(log, held, routes, loaded.db)
    opts = AnalysisOptions(whole_log=False)
    plain = run_analysis(log, VehicleInputs(PAPER, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml"), opts)
    timed = run_analysis(log, VehicleInputs(PAPER, DBC / "lashscope_ev.dbc", _with_time_base(tmp_path)), opts)
    assert [f.code for f in plain.findings] == []
    (finding,) = timed.findings
    assert (finding.code, finding.channel) == ("speed_retimed", "motor_speed_rpm")
    assert finding.message.startswith("motor_speed_rpm re-timed from time_base: the logged stamps were off by up "
                                      "to 11")
    logged = plain.signals["motor_speed_rpm"].t  # on the log's clock, which starts at its first frame
    sampled = sp.t - float(np.median(sp.t - logged))
    got = timed.signals["motor_speed_rpm"].t
    assert got.size == sp.t.size
    assert float(np.max(np.abs(got - sampled))) < 6e-4  # the sampling jitter is 0.3 ms
    assert float(np.max(np.abs(logged - sampled))) > 0.1


def test_a_time_base_outside_the_speed_message_is_refused(tmp_path: Path) -> None:
    from app.errors import SignalMapError
    from app.pipeline import signal_routes

    smap = tmp_path / "bad.map.toml"
    smap.write_text((DBC / "lashscope_ev.map.toml").read_text(encoding="utf-8")
                    + '\n[channels.time_base]\nmessage = "MCU_Torque"\nsignal = "MCU_TorqueAlive"\n', encoding="utf-8")
    with pytest.raises(SignalMapError, match=r"channel time_base: MCU_Torque.MCU_TorqueAlive must be a signal of the "
                       r"motor speed's message \(MCU_Speed\)"):
        signal_routes(DBC / "lashscope_ev.dbc", smap)
