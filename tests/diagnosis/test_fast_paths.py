"""The fit's cheaper per-pass paths give the reference path's numbers bit for bit.

A fit's pass runs the simulator through :func:`sim.simulate.simulate_speed` (no assembly of the outputs a fit
never reads), keeps the residuals of the last points it met (a point met again is not simulated again) and
runs with one BLAS thread (:mod:`app.analysis.blas_threads`). Each is checked here against the path it
replaces, on a simulated drive with a real effect in it.
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import cache

import numpy as np
import pytest

from app.analysis import blas_threads
from app.analysis.diagnosis import calibrate, forward
from app.analysis.diagnosis.calibrate import Bounds, _Problem, fit
from app.analysis.diagnosis.forward import (
    DiagEvent,
    Nuisance,
    SimOut,
    best_offset,
    shifted_chi2,
    shifted_chi2_compiled,
    simulate_events,
    vehicle_with,
)
from app.analysis.diagnosis.offset_kernel import shifted_residuals
from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS, prepare
from app.analysis.diagnosis.split import make_split
from app.analysis.events import detect_events
from sim import load_vehicle, simulate
from sim.effects import apply_effects, get_effect
from sim.simulate import simulate_speed
from tests.diagnosis.conftest import drive_signals, paper
from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

TRUTH = (("coulomb_nm", 4.0), ("viscous_nms", 0.01))


@cache
def _calibration() -> tuple[list[DiagEvent], Bounds, object]:
    sig = drive_signals("drag", TRUTH, 31, 20.0)
    events, noise, _ = prepare(sig, detect_events(sig, DIAGNOSIS_EVENTS))
    split = make_split(events, seed=1)
    return split.calibration_events(events), Bounds.for_period(noise.period_s), split


@pytest.fixture
def reference_paths(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """Inside: the full SimResult per run, the numpy offset profile, no residual memo and the points one after the
    other (what the fit did before); :func:`_fast` switches to the default paths, with two simulation threads
    even on a one-core machine."""
    monkeypatch.setattr(forward, "SIM_THREADS", 2)
    lean, memo, par = forward.LEAN_SIM, calibrate.MEMO_POINTS, calibrate.PARALLEL_POINTS
    forward.LEAN_SIM, calibrate.MEMO_POINTS, calibrate.PARALLEL_POINTS = False, 0, False
    try:
        yield
    finally:
        forward.LEAN_SIM, calibrate.MEMO_POINTS, calibrate.PARALLEL_POINTS = lean, memo, par


def _fast() -> None:
    forward.LEAN_SIM, calibrate.MEMO_POINTS, calibrate.PARALLEL_POINTS = True, 8, True


@pytest.mark.parametrize("effects", [{}, {"speed_sensor": {"tau_s": 0.003, "delay_s": 0.004}},
                                     {"tyre_slip": {"compliance_per_mn": 20.0, "relaxation_m": 0.2}},
                                     {"torque_gain": {}}])
def test_simulate_speed_is_simulate_s_speed_and_gaps(effects: dict[str, dict[str, float]]) -> None:
    """... for a vehicle whose logged torque is not the air-gap torque too (an identified ``torque_gain``)."""
    if "torque_gain" in effects:
        v = load_vehicle("paper").with_changes({"motor.torque_gain": 0.85})
    else:
        v = apply_effects(load_vehicle("paper"), effects) if effects else load_vehicle("paper")
    t = np.arange(0.0, 3.0, 0.01)
    q = np.where(t < 1.0, -30.0, 90.0) + 5.0 * np.sin(7.0 * t)
    full = simulate(v, t, q, speed0_rpm=1500.0, interp="linear")
    lean = simulate_speed(v, t, q, speed0_rpm=1500.0, interp="linear")
    assert np.array_equal(lean.t, full.t)
    assert np.array_equal(lean.motor_speed_rpm, full.motor_speed_rpm)
    assert lean.gap_open.keys() == full.gap_open.keys()
    assert any(m.any() and not m.all() for m in full.gap_open.values())  # the gaps open and close in this drive
    for g, m in full.gap_open.items():
        assert np.array_equal(lean.gap_open[g], m)
    speed_only = simulate_speed(v, t, q, speed0_rpm=1500.0, interp="linear", gaps=False)
    assert np.array_equal(speed_only.motor_speed_rpm, full.motor_speed_rpm) and speed_only.gap_open == {}


def test_lean_runs_give_every_event_the_same_output() -> None:
    cal, _, _ = _calibration()
    drag = get_effect("drag")
    settings = ((drag, drag.values([3.0, 0.02])),)
    veh = vehicle_with(paper(), Nuisance(0.0, 1.02, 0.3), settings)
    lean = simulate_events(cal, veh, 1.02, settings)
    forward.LEAN_SIM = False
    try:
        full = simulate_events(cal, veh, 1.02, settings)
    finally:
        forward.LEAN_SIM = True
    assert len(lean) == len(full) == len(cal)
    speed_only = simulate_events(cal, veh, 1.02, settings, gaps=False)
    for a, b, c in zip(lean, full, speed_only, strict=True):
        assert np.array_equal(a.t, b.t) and np.array_equal(a.speed, b.speed)
        assert a.gap_open is not None and b.gap_open is not None and np.array_equal(a.gap_open, b.gap_open)
        assert np.array_equal(c.t, b.t) and np.array_equal(c.speed, b.speed) and c.gap_open is None


def _problem(cal: list[DiagEvent], bounds: Bounds) -> _Problem:
    return _Problem(paper(), cal, (get_effect("drag"),), bounds, "multibody")


def test_residuals_offset_and_jacobian_equal_the_reference_path(reference_paths: None) -> None:
    cal, bounds, _ = _calibration()
    u = np.array([0.47, 0.55, 0.3, 0.4])
    ref = _problem(cal, bounds)
    r_ref = ref.residuals(u)
    off_ref = ref.last_offset
    j_ref = ref.jacobian(u, r_ref)
    _fast()
    new = _problem(cal, bounds)
    r_new = new.residuals(u)
    off_new = new.last_offset
    ran = _count_ahead(new)
    j_new = new.jacobian(u, r_new)
    assert ran == [u.size]  # the columns ran ahead, side by side
    assert np.array_equal(r_new, r_ref)
    assert off_new == off_ref and bounds.offset_s[0] < off_new < bounds.offset_s[1]
    assert np.array_equal(j_new, j_ref)
    assert np.all(np.abs(j_new).max(axis=0) > 0)  # every column moves the residual: a real Jacobian
    assert new.nfev == ref.nfev == u.size + 1


def _count_ahead(prob: _Problem) -> list[int]:
    """Records how many points each run_ahead of ``prob`` left for residuals to take."""
    counts: list[int] = []
    real = prob.run_ahead

    def spy(points: list[np.ndarray]) -> None:
        real(points)
        counts.append(len(prob._ahead))

    prob.run_ahead = spy  # type: ignore[method-assign]
    return counts


def test_a_point_met_again_returns_its_residual_and_offset_and_counts_as_a_pass() -> None:
    cal, bounds, _ = _calibration()
    prob = _problem(cal, bounds)
    u, v = np.array([0.5, 0.5, 0.2, 0.2]), np.array([0.5, 0.52, 0.2, 0.2])
    r1 = prob.residuals(u)
    off1 = prob.last_offset
    assert not np.array_equal(prob.residuals(v), r1)  # another point in between
    again = prob.residuals(u)
    assert np.array_equal(again, r1) and again is not r1
    assert prob.last_offset == off1
    assert prob.nfev == 3
    again[:] = 0.0  # the caller's copy: the memo keeps its own
    assert np.array_equal(prob.residuals(u), r1)


def test_a_fit_with_the_memo_is_the_fit_without(reference_paths: None) -> None:
    cal, bounds, split = _calibration()
    ref = fit(paper(), cal, split, (get_effect("drag"),), bounds=bounds)
    _fast()
    seen: list[int] = []
    real = _Problem.run_ahead

    def spy(self: _Problem, points: list[np.ndarray]) -> None:
        real(self, points)
        seen.append(len(self._ahead))

    _Problem.run_ahead = spy  # type: ignore[method-assign]
    try:
        new = fit(paper(), cal, split, (get_effect("drag"),), bounds=bounds)
    finally:
        _Problem.run_ahead = real  # type: ignore[method-assign]
    assert len(seen) > 3 and max(seen) >= 4  # the screen's starts and the Jacobians' columns ran ahead
    assert new.values == ref.values and new.nuisance == ref.nuisance
    assert new.chi2 == ref.chi2 and new.nfev == ref.nfev
    assert new.residual is not None and ref.residual is not None and np.array_equal(new.residual, ref.residual)
    assert new.jac is not None and ref.jac is not None and np.array_equal(new.jac, ref.jac)
    assert new.values["drag"]["coulomb_nm"] == pytest.approx(4.0, rel=0.5)  # and it found the drag


def test_one_blas_thread_inside_the_block_and_the_count_restored_after() -> None:
    import scipy.linalg  # noqa: F401  (scipy's own OpenBLAS loaded too)

    libs = blas_threads._loaded_openblas()
    if not libs:
        pytest.skip("no OpenBLAS loaded in this process (another BLAS)")
    before = [get() for _, get in libs]
    for set_fn, _ in libs:
        set_fn(2)
    try:
        with blas_threads.single_blas_thread():
            assert [get() for _, get in libs] == [1] * len(libs)
            with blas_threads.single_blas_thread():  # nested: still one, and the outer block restores
                pass
            assert [get() for _, get in libs] == [1] * len(libs)
        assert [get() for _, get in libs] == [2] * len(libs)
    finally:
        for (set_fn, _), n in zip(libs, before, strict=True):
            set_fn(n)


def test_blas_threads_left_alone_when_disabled() -> None:
    libs = blas_threads._loaded_openblas()
    if not libs:
        pytest.skip("no OpenBLAS loaded in this process (another BLAS)")
    before = [get() for _, get in libs]
    blas_threads.ENABLED = False
    try:
        with blas_threads.single_blas_thread():
            assert [get() for _, get in libs] == before
    finally:
        blas_threads.ENABLED = True




@cache
def _calibration_1khz() -> tuple[list[DiagEvent], Bounds]:
    """A 1 kHz log (the offset grid of +-20 ms holds 81 offsets) of a drive with a drag."""
    v = paper()
    rng = np.random.default_rng(5)
    drive = make_drive(v, rng, DriveSpec(duration_s=12.0))
    sig = to_signals(measure(drive, run_truth(apply_effects(v, {"drag": dict(TRUTH)}), drive),
                             CanSampling(period_s=0.001, offset_s=0.004), rng))
    events, noise, _ = prepare(sig, detect_events(sig, DIAGNOSIS_EVENTS))
    return events, Bounds.for_period(noise.period_s)


@pytest.mark.parametrize("which", ["100 Hz", "1 kHz"])
def test_the_compiled_offset_profile_is_numpy_s_bit_for_bit(which: str) -> None:
    cal, bounds = _calibration_1khz() if which == "1 kHz" else _calibration()[:2]
    grid = np.arange(bounds.offset_s[0], bounds.offset_s[1] + 0.00025, 0.0005)
    assert grid.size == 81  # +-20 ms at either rate (the bound's floor)
    drag = get_effect("drag")
    for gain, grade, vals in ((1.0, 0.0, [0.0, 0.0]), (1.04, 0.5, [4.0, 0.01]), (0.93, -0.8, [1.0, 0.02])):
        settings = ((drag, drag.values(vals)),)
        outs = simulate_events(cal, vehicle_with(paper(), Nuisance(0.0, gain, grade), settings), gain, settings,
                               gaps=False)
        ref = shifted_chi2(cal, outs, grid)
        assert np.array_equal(shifted_chi2_compiled(cal, outs, grid), ref)
        assert 0 < int(np.argmin(ref)) < grid.size - 1 or which == "100 Hz"  # an inner minimum at 1 kHz
        forward.LEAN_SIM = False
        try:
            off_ref = best_offset(cal, outs, bounds.offset_s)
        finally:
            forward.LEAN_SIM = True
        assert best_offset(cal, outs, bounds.offset_s) == off_ref


def test_the_offset_kernel_interpolates_as_numpy_at_the_ends_on_grid_points_and_around_nan() -> None:
    xp = np.array([0.0, 0.001, 0.002, 0.003, 0.004, 0.005])
    fp = np.array([1.0, 2.5, np.nan, 4.0, 4.0, -3.0])
    t = np.array([-0.01, 0.0, 0.0005, 0.001, 0.0015, 0.0025, 0.0035, 0.0049, 0.005, 0.02])
    meas = np.linspace(-1.0, 1.0, t.size)
    offsets = np.array([-0.0015, -0.0005, 0.0, 0.001, 0.0031])
    r = np.empty((offsets.size, t.size))
    shifted_residuals(t, meas, xp, fp, offsets, r)
    want = meas[None, :] - np.interp((t[None, :] - offsets[:, None]).ravel(), xp, fp).reshape(r.shape)
    assert np.array_equal(r, want, equal_nan=True)
    assert np.isnan(r).any() and np.isfinite(r).any()
    one = np.empty((1, 3))  # a one-point grid: its value everywhere
    shifted_residuals(np.array([-1.0, 0.0, 1.0]), np.zeros(3), np.array([0.0]), np.array([7.0]), np.zeros(1), one)
    assert np.array_equal(one, -np.interp(np.array([[-1.0, 0.0, 1.0]]), np.array([0.0]), np.array([7.0])))


def test_simout_time_grid_is_what_the_kernel_needs() -> None:
    cal, _, _ = _calibration()
    out = simulate_events(cal[:1], paper(), 1.0, gaps=False)[0]
    assert isinstance(out, SimOut) and np.all(np.diff(out.t) > 0)  # strictly increasing: the cursor's bracket


def test_rank_one_updates_take_fewer_passes_and_leave_a_full_jacobian_at_the_solution(
        monkeypatch: pytest.MonkeyPatch) -> None:
    cal, bounds, split = _calibration()
    every = fit(paper(), cal, split, (get_effect("drag"),), bounds=bounds)
    monkeypatch.setattr(calibrate, "BROYDEN_EVERY", 3)
    seen: list[bool] = []
    real = calibrate._Broyden.__call__

    def spy(self: calibrate._Broyden, x: np.ndarray) -> np.ndarray:
        jac = real(self, x)
        seen.append(self.fresh)
        return jac

    monkeypatch.setattr(calibrate._Broyden, "__call__", spy)
    upd = fit(paper(), cal, split, (get_effect("drag"),), bounds=bounds)
    assert False in seen and True in seen  # updates between finite-difference Jacobians
    assert upd.nfev < every.nfev
    assert upd.values["drag"]["coulomb_nm"] == pytest.approx(4.0, rel=0.5)
    # the reported Jacobian is the finite-difference one at the solution, not the last rank-one update (off by
    # percents): the solution is re-encoded from its reported values, and that round trip through the physical units
    # may move a unit-box coordinate by an ulp, which the finite difference turns into a few 1e-7 of its column
    prob = _problem(cal, bounds)
    u = prob.encode(upd.nuisance, upd.values)
    fresh = prob.jacobian(u, prob.residuals(u))
    assert upd.jac is not None
    assert np.all(np.abs(upd.jac - fresh).max(axis=0) <= 1e-5 * np.abs(fresh).max(axis=0))
