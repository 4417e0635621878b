"""Physical limits, run budgets, plain error messages, GIL-free kernels and the what-if/tolerance CLI."""

from __future__ import annotations

import threading
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from sim import InputSignalError, ParameterError, WhatIf, load_vehicle, load_vehicle_text, simulate
from sim.batch import simulate_batch, tolerance_analysis
from sim.budget import MAX_OUTPUT_BYTES, MAX_STEPS
from sim.inputs import prepare_input
from sim.integrate import _initial_forces, run_chain, run_chain_batch
from sim.two_inertia import run_two_inertia
from sim.vehicle_file import dump_toml
from sim.whatif import parse_what_if

PAPER = load_vehicle("paper")
TIP_T = np.array([0.0, 0.2, 0.21, 0.6])
TIP_Q = np.array([-40.0, -40.0, 80.0, 80.0])


def _edit(old: str, new: str) -> str:
    text = dump_toml(PAPER)
    assert old in text
    return text.replace(old, new, 1)


def test_huge_stiffness_in_a_file_is_refused_with_its_range() -> None:
    text = _edit("mesh2_stiffness = 3000000.0", "mesh2_stiffness = 1e30")
    with pytest.raises(ParameterError, match=r"reducer\.mesh2_stiffness = 1e\+30: outside the physical range "
                                             r"\[1, 1e\+09\]") as err:
        load_vehicle_text(text)
    assert err.value.field == "reducer.mesh2_stiffness"


@pytest.mark.parametrize(("path", "value", "match"), [
    ("halfshaft.segments", 100000, r"halfshaft\.segments = 100000: outside the physical range \[1, 20\]"),
    ("motor.rotor_inertia", 1e-12, r"motor\.rotor_inertia = 1e-12: outside"),
    ("body.mass", 1e9, r"body\.mass = 1000000000\.0: outside"),
    ("wheel.radius", 30.0, r"wheel\.radius = 30\.0: outside the physical range \[0\.05, 2\] m"),
    ("halfshaft.damping", 1e12, r"halfshaft\.damping = 1000000000000\.0: outside"),
    ("reducer.teeth", (27, 79, 20, 5000), r"reducer\.teeth\[3\] = 5000: outside"),
    ("reducer.teeth", (79, 27, 77, 20), r"reducer\.teeth = \[79, 27, 77, 20\]: total ratio 0\.08877"),
    ("effects.progressive_stiffness.mesh2", 1e20, r"progressive_stiffness\.mesh2 = 1e\+20: outside"),
])
def test_field_limits(path: str, value: object, match: str) -> None:
    with pytest.raises(ParameterError, match=match):
        PAPER.with_changes({path: value})


def test_gap_nominal_must_lie_in_its_band_and_below_the_physical_limit() -> None:
    text = _edit("[gaps.halfshaft]\nnominal = 0.024", "[gaps.halfshaft]\nnominal = 0.5")
    with pytest.raises(ParameterError, match=r"gaps\.halfshaft\.nominal = 0\.5: outside the physical range \[0, 0\.2"):
        load_vehicle_text(text)
    text = _edit("[gaps.halfshaft]\nnominal = 0.024", "[gaps.halfshaft]\nnominal = 0.05")
    with pytest.raises(ParameterError, match=r"gaps\.halfshaft\.nominal = 0\.05: must lie within its tolerance band "
                                             r"\[min, max\] = \[0\.016, 0\.032\]"):
        load_vehicle_text(text)
    # a what-if moving a gap outside its band widens the band; an explicit band is checked as given
    wider = PAPER.with_changes({"gaps.halfshaft": 0.05})
    assert (wider.gaps.halfshaft.min, wider.gaps.halfshaft.max) == (0.016, 0.05)
    with pytest.raises(ParameterError, match=r"gaps\.halfshaft\.nominal = 0\.05: must lie within"):
        PAPER.with_changes({"gaps.halfshaft": 0.05, "gaps.halfshaft.max": 0.04})


def test_tolerance_bands_must_stay_within_the_field_limits() -> None:
    text = _edit('"halfshaft.stiffness" = [6800.0, 9200.0]', '"halfshaft.stiffness" = [6800.0, 1e30]')
    with pytest.raises(ParameterError, match=r"tolerances\.halfshaft\.stiffness\[max\] = 1e\+30: outside"):
        load_vehicle_text(text)


def test_step_budget_refuses_a_stiff_valid_vehicle_before_integrating() -> None:
    stiff = PAPER.with_changes({"reducer.diff_stiffness": 1e9, "reducer.side_gears_inertia": 1e-6})
    t = np.array([0.0, 1000.0])
    with pytest.raises(ParameterError, match=r"^dt = .*integrator steps for 1000 s of input \(run\) exceed the budget "
                                             r"of 2e\+08 steps; the automatic step follows the stiffest mode") as err:
        simulate(stiff, t, [10.0, 10.0], output_dt=0.01)
    assert err.value.field == "dt"
    with pytest.raises(ParameterError, match=r"exceed the budget"):
        simulate(PAPER, t, [10.0, 10.0], dt=1e-7, output_dt=0.01)
    with pytest.raises(ParameterError, match=r"variant 1\) exceed the budget"):
        simulate_batch(PAPER, [{}, {"reducer.diff_stiffness": 1e9, "reducer.side_gears_inertia": 1e-6}], t,
                       [10.0, 10.0], output_dt=0.01)
    # the whole Monte Carlo is priced before its first batch
    with pytest.raises(ParameterError, match=r"1001 variants at the nominal step\) exceed the budget of 2e\+09"):
        tolerance_analysis(PAPER, [0.0, 200.0], [10.0, 10.0], n=1000, output_dt=0.05)
    assert MAX_STEPS == 200_000_000


@pytest.mark.parametrize(("t", "output_dt", "model"), [
    ([0.0, 1e9], 0.001, "multibody"), ([0.0, 1e9], 1.0, "two_inertia"), ([0.0, 1.0], 1e-12, "multibody"),
])
def test_output_budget_refuses_before_allocating(t: list[float], output_dt: float, model: str) -> None:
    budget = f"{MAX_OUTPUT_BYTES / 2**20:.0f} MiB"
    with pytest.raises(InputSignalError, match=rf"output samples, .* MiB of output, over the budget of {budget}"):
        simulate(PAPER, t, [10.0, 10.0], output_dt=output_dt, model=model)
    with pytest.raises(InputSignalError, match=r"over the budget"):
        simulate_batch(PAPER, [{}], t, [10.0, 10.0], output_dt=output_dt)


def test_antijerk_resampling_is_budgeted() -> None:
    with pytest.raises(InputSignalError, match=r"anti-jerk shaping resamples"):
        WhatIf(antijerk_rate=100.0).apply_torque(np.array([0.0, 1e8]), np.array([1.0, -1.0]))


def test_messages_show_plain_numbers() -> None:
    with pytest.raises(InputSignalError) as err:
        prepare_input(np.array([0.0, 0.5, 0.5]), np.zeros(3))
    assert str(err.value) == "t_s[2] = 0.5 <= t_s[1] = 0.5: times must strictly increase"
    with pytest.raises(InputSignalError, match=r"torque_nm\[1\] = nan at"):
        prepare_input([0.0, 1.0], [1.0, np.nan])
    exc = ParameterError("body.mass", np.float64(1e9), "too heavy")
    assert str(exc) == "body.mass = 1000000000.0: too heavy" and type(exc.value) is float
    assert "np." not in str(ParameterError("x", (np.float64(1.0), np.int64(2)), "r"))
    with pytest.raises(ParameterError) as perr:
        PAPER.with_changes({"body.mass": np.float64(1e9)})
    assert "np." not in str(perr.value)


def test_kernels_release_the_gil() -> None:
    for kernel in (run_chain, run_chain_batch, _initial_forces, run_two_inertia):
        assert kernel.targetoptions.get("nogil") is True, kernel
        assert type(kernel._cache).__name__ == "FunctionCache", kernel  # cache=True: compiled code on disk
    # the kernels run concurrently in threads and give the serial result
    serial = simulate(PAPER, TIP_T, TIP_Q).motor_speed_rpm
    out: list[np.ndarray] = []
    threads = [threading.Thread(target=lambda: out.append(simulate(PAPER, TIP_T, TIP_Q).motor_speed_rpm))
               for _ in range(2)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(out) == 2 and all(np.array_equal(o, serial) for o in out)


def test_parse_what_if() -> None:
    w = parse_what_if(["gap=halfshaft:0.5,torque=0.8", "anti_jerk=2000, gap=all:0.9", "set=body.mass:2000"])
    assert dict(w.gap_scale) == {"halfshaft": 0.5, "all": 0.9} and w.torque_scale == 0.8
    assert w.antijerk_rate == 2000.0 and dict(w.changes) == {"body.mass": 2000}
    assert w.apply_vehicle(PAPER).gaps.halfshaft.nominal == pytest.approx(0.024 * 0.45)
    for bad, match in [("gap=hub:0.5", r"what_if\.gap_scale\.hub"), ("torque=x", r"what_if\.torque = 'x'"),
                       ("speed=3", r"what_if = 'speed=3'"), ("gap=halfshaft", r"what_if\.gap = 'halfshaft'")]:
        with pytest.raises(ParameterError, match=match):
            parse_what_if([bad]).apply_vehicle(PAPER)  # gap names are the vehicle's: checked when applied


def test_tolerance_progress_and_chunks_match_one_batch(monkeypatch: pytest.MonkeyPatch) -> None:
    import sim.batch as batch

    calls: list[tuple[int, int]] = []
    whole = tolerance_analysis(PAPER, TIP_T, TIP_Q, n=5, seed=3)
    monkeypatch.setattr(batch, "TOLERANCE_CHUNK", 2)
    chunked = tolerance_analysis(PAPER, TIP_T, TIP_Q, n=5, seed=3, progress=lambda d, n: calls.append((d, n)))
    assert calls == [(0, 5), (2, 5), (4, 5), (5, 5)]
    assert np.array_equal(whole.fluct_rpm, chunked.fluct_rpm) and whole.nominal_fluct_rpm == chunked.nominal_fluct_rpm
    one = simulate_batch(PAPER, [dict(zip(whole.fields, map(float, whole.samples[4]), strict=True))], TIP_T, TIP_Q)
    from sim.metrics import peak_to_valley
    assert peak_to_valley(one.t, one.motor_speed_rpm[0]) == pytest.approx(whole.fluct_rpm[4], abs=1e-9)


@pytest.fixture
def torque_csv(tmp_path: Path) -> Path:
    path = tmp_path / "torque.csv"
    path.write_text("t_s,torque_nm\n" + "".join(f"{t},{q}\n" for t, q in zip(TIP_T, TIP_Q, strict=True)))
    return path


def test_cli_what_if_and_tolerance(torque_csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", str(torque_csv), "--what-if", "gap=halfshaft:0.5,torque=0.8,anti_jerk=2000"]) == 0
    out = capsys.readouterr().out
    assert "baseline: motor speed" in out and "what-if gap=halfshaft:0.5,torque=0.8,anti_jerk=2000:" in out
    assert "% of the baseline's" in out
    assert main(["tolerance", str(torque_csv), "--vehicle", "paper", "--n", "150", "--seed", "1",
                 "--measured-ripple", "1e6"]) == 0
    cap = capsys.readouterr()
    assert "tolerance: 0/150 variants" in cap.err and "tolerance: 150/150 variants" in cap.err
    assert "predicted 5 %" in cap.out and "percentile 100.0 of the prediction (above the band)" in cap.out
    res = tolerance_analysis(PAPER, TIP_T, TIP_Q, n=150, seed=1)
    p50 = float(np.percentile(res.fluct_rpm, 50))
    assert f"50 % {p50:.1f}" in cap.out
    assert "felt shuffle peak-to-peak (body acceleration): nominal" in cap.out
    assert "felt (body acceleration, baseline -> what-if): shuffle peak-to-peak" in out


@pytest.mark.parametrize(("args", "message"), [
    (["--vehicle", "{bad}"], "halfshaft.segments = 100000: outside the physical range [1, 20]"),
    (["--output-dt", "1e-12"], f"over the budget of {MAX_OUTPUT_BYTES / 2**20:.0f} MiB"),
    (["--what-if", "gap=hub:2"], "what_if.gap_scale.hub = 2.0"),
])
def test_cli_errors_are_one_line(args: list[str], message: str, torque_csv: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text(_edit("segments = 2", "segments = 100000"))
    args = [a.replace("{bad}", str(bad)) for a in args]
    assert main(["simulate", str(torque_csv), *args]) == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err and "np.float64" not in err
