"""Model-free modal estimate (app/identify/modal.py) against generators that share none of its equations.

(a) A two-mass torsional system (motor and vehicle inertia on a damped shaft) simulated with
scipy's exact first-order-hold discretisation, its mode set by (f, zeta), sampled as CAN loggers
do: 1 kHz, 50 Hz with frames held back and written in bursts of 2-4, and 20 Hz, with timestamp
jitter, sensor noise and 0.5 rpm quantisation. (b) The independent generator of ``bench/indep``
(its own multibody equations of the paper car), whose shuffle is compared with the eigenvalues of
its own linearisation. (c) Input that gives no mode.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import signal

from app.analysis.diagnosis.prepare import DIAGNOSIS_EVENTS
from app.analysis.events import detect_events
from app.errors import InputError, InsufficientDataError
from app.identify.modal import (
    EventWindow,
    ModalEstimate,
    estimate_modes,
    lash_closed_segment,
    modes_from_signals,
    pooled_mode,
    window_estimate,
    window_mode,
)
from app.ingest.database import load_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.signalmap import REQUIRED, load_signal_map
from bench.indep.car import nominal_car
from bench.indep.drive import BAND_A, make_drive
from bench.indep.dynamics import N_STATE, _rhs, initial_state, pack, simulate
from bench.indep.record import DBC, MAP, write_drive
from tests.conftest import shared_file
from tests.support.truthlog import read_log

RPM = 30.0 / np.pi
J_MOTOR = 0.12  # kg m^2: rotor and reducer at the motor
J_VEHICLE = 1.5  # kg m^2: the vehicle at the motor
FINE_S = 2e-4  # s, simulation grid


def two_mass(f_hz: float, zeta: float) -> signal.StateSpace:
    """Motor speed (rpm) of two inertias on a shaft whose free-free mode is (f_hz, zeta), driven by motor torque.

    States: shaft twist, motor speed, vehicle speed. The mode of ``J1 J2 / (J1 + J2)`` on ``k``
    and ``c``: ``omega_n^2 = k / J_r``, ``zeta = c / (2 J_r omega_n)``.
    """
    wn = 2 * np.pi * f_hz
    jr = J_MOTOR * J_VEHICLE / (J_MOTOR + J_VEHICLE)
    k, c = wn**2 * jr, 2 * zeta * wn * jr
    a = np.array([[0.0, 1.0, -1.0],
                  [-k / J_MOTOR, -c / J_MOTOR, c / J_MOTOR],
                  [k / J_VEHICLE, c / J_VEHICLE, -c / J_VEHICLE]])
    return signal.StateSpace(a, [[0.0], [1.0 / J_MOTOR], [0.0]], [[0.0, RPM, 0.0]], [[0.0]])


@functools.cache
def _discrete(f_hz: float, zeta: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact first-order-hold discretisation of :func:`two_mass` on the simulation grid, as a filter."""
    ss = two_mass(f_hz, zeta)
    ad, bd, cd, dd, _ = signal.cont2discrete((ss.A, ss.B, ss.C, ss.D), FINE_S, method="foh")
    num, den = signal.ss2tf(ad, bd, cd, dd)
    return num[0], den


def logged_stamps(rng: np.random.Generator, t: np.ndarray, period: float, bursty: bool) -> np.ndarray:
    """Logger timestamps of frames sampled at ``t``: one-sided jitter, and (``bursty``) runs of 2-4
    frames held back and written back-to-back 0.1 ms apart when the last of them arrives."""
    out = t + np.abs(rng.normal(0.0, 1e-4, t.size))
    i = 5
    while bursty and i < t.size - 5:
        if rng.random() < 0.3:
            k = int(rng.integers(2, 5))
            out[i:i + k] = out[i + k - 1] + 1e-4 * np.arange(k)
            i += k + 2
        else:
            i += 1
    return out


def make_window(rng: np.random.Generator, f_hz: float, zeta: float, fs: float, bursty: bool,
                direction: float, post_s: float = 1.0) -> EventWindow:
    """One torque reversal through zero at 0.5 s (ramp 400-1200 N m/s between drawn levels), logged at ``fs``."""
    t_cross = 0.5
    t = np.arange(0.0, t_cross + post_s + 0.05, FINE_S)
    rate = rng.uniform(400.0, 1200.0)
    lo, hi = -rng.uniform(15.0, 40.0), rng.uniform(30.0, 80.0)
    torque = np.clip(direction * (t - t_cross) * rate, lo, hi)
    speed = signal.lfilter(*_discrete(f_hz, zeta), torque)
    period = 1.0 / fs
    ts = rng.uniform(0, period) + np.arange(0.0, t[-1] - period, period)
    sp = np.round((2000.0 + np.interp(ts, t, speed) + rng.normal(0, 0.5, ts.size)) / 0.5) * 0.5
    tt = rng.uniform(0, period) + np.arange(0.0, t[-1] - period, period)
    tq = np.round((np.interp(tt, t, torque) + rng.normal(0, 0.3, tt.size)) / 0.1) * 0.1
    return EventWindow(speed_t=logged_stamps(rng, ts, period, bursty), speed_rpm=sp,
                       torque_t=logged_stamps(rng, tt, period, bursty), torque_nm=tq, t_cross=t_cross,
                       direction=direction)


def make_log(seed: int, f_hz: float, zeta: float, fs: float, bursty: bool, n: int = 6) -> list[EventWindow]:
    """``n`` alternating tip-ins and tip-outs of one vehicle."""
    rng = np.random.default_rng(seed)
    return [make_window(rng, f_hz, zeta, fs, bursty, 1.0 if i % 2 == 0 else -1.0) for i in range(n)]


CASES = [  # (f Hz, zeta, sampling Hz, bursty)
    (2.5, 0.3, 1000.0, False), (8.0, 0.05, 1000.0, False),
    (2.5, 0.3, 50.0, True), (8.0, 0.05, 50.0, True),
    (2.5, 0.3, 20.0, False), (5.0, 0.1, 20.0, False),
]


@pytest.mark.parametrize(("f_hz", "zeta", "fs", "bursty"), CASES)
def test_mode_of_a_two_mass_system(f_hz, zeta, fs, bursty):
    est = estimate_modes(make_log(7, f_hz, zeta, fs, bursty))
    assert est.freq_hz == pytest.approx(f_hz, rel=0.05)
    assert est.zeta == pytest.approx(zeta, rel=0.2)
    assert est.n_windows == 6 and est.n_used >= 4
    assert est.freq_ci[0] < est.freq_hz < est.freq_ci[1] and est.zeta_ci[0] < est.zeta < est.zeta_ci[1]
    for m in est.windows:
        assert m.fs_hz == pytest.approx(min(fs, 100.0), rel=0.02)  # 1 kHz decimated, slow channels kept
        assert m.fit_r2 > 0.9 and m.freq_ci[0] < m.freq_hz < m.freq_ci[1]
        assert m.freq_hz == pytest.approx(f_hz, rel=0.1)


def test_pooled_interval_coverage():
    """The 90 % intervals of logs of five windows cover the truth about 90 % of the time: 40 logs each of a
    50 Hz bursty channel (5 Hz, zeta 0.15) and a 1 kHz one (8 Hz, zeta 0.05)."""
    hits = []
    for f_hz, zeta, fs, bursty in ((5.0, 0.15, 50.0, True), (8.0, 0.05, 1000.0, False)):
        for seed in range(40):
            est = estimate_modes(make_log(1000 + seed, f_hz, zeta, fs, bursty, n=5))
            hits.append((est.freq_ci[0] <= f_hz <= est.freq_ci[1], est.zeta_ci[0] <= zeta <= est.zeta_ci[1]))
    cover_f, cover_z = np.mean(hits, axis=0)
    assert 0.75 <= cover_f <= 0.99
    assert 0.75 <= cover_z <= 0.99


def test_pooling_over_logs_and_the_result_as_json():
    windows = [m for seed in (1, 2) for m in (window_mode(w) for w in make_log(seed, 5.0, 0.15, 50.0, True, 4))]
    modes = [m for m in windows if not isinstance(m, str)]
    both = pooled_mode(modes, rejected=[(3.0, "a reason")])
    assert both.n_windows == len(modes) + 1 and both.n_used == len(modes) == 8
    assert both.rejected == ((3.0, "a reason"),)
    assert both.freq_hz == pytest.approx(5.0, rel=0.05) and both.freq_ci[0] < 5.0 < both.freq_ci[1]
    d = json.loads(json.dumps(both.to_dict()))
    assert d["freq_hz"] == pytest.approx(both.freq_hz) and d["rejected"][-1] == {"t_event": 3.0, "reason": "a reason"}
    assert len(d["windows"]) == both.n_used and d["windows"][0]["order"] == list(both.windows[0].order)


def test_an_outlying_window_is_set_aside():
    modes = [m for m in map(window_mode, make_log(3, 5.0, 0.15, 50.0, True, 6)) if not isinstance(m, str)]
    wrong = modes[0].__class__(**{**modes[0].__dict__, "freq_hz": 9.0, "freq_ci": (8.9, 9.1), "t_event": 9.9})
    est = pooled_mode([*modes, wrong])
    assert est.n_used == len(modes) and est.rejected[0][0] == 9.9 and "outlier" in est.rejected[0][1]
    assert est.freq_hz == pytest.approx(5.0, rel=0.02)


def test_the_lash_closed_segment_is_the_first_excursion_after_the_crossing():
    """A tip-in, a tip-out at 1.0-1.1 s and a larger tip-in at 1.4 s: the segment runs from where the first
    tip-in's torque leaves the band to where the tip-out brings it back, whatever comes later."""
    t = np.arange(0.0, 2.0, 0.02)
    torque = np.interp(t, [0.0, 0.5, 0.6, 1.0, 1.1, 1.4, 1.5, 2.0],
                       [-30.0, -30.0, 60.0, 60.0, -30.0, -30.0, 150.0, 150.0])
    torque[(t > 0.5) & (t < 0.56)] = 5.0  # dithering on the band's edge on the way up
    seg = lash_closed_segment(EventWindow(t, 2000.0 + t, t, torque, t_cross=0.5 - 30 / 900, direction=1.0))
    assert not isinstance(seg, str) and seg.dt == pytest.approx(0.02)
    assert seg.start * seg.dt == pytest.approx(0.56, abs=1e-6)  # first sample past the dither
    assert seg.speed_rpm.size * seg.dt == pytest.approx(1.08, abs=1e-6)  # up to the tip-out's band entry


# --- input that gives no mode ---------------------------------------------------------------------


def _with(w: EventWindow, **changes: object) -> EventWindow:
    return EventWindow(**{**w.__dict__, **changes})


@pytest.fixture(scope="module")
def good() -> EventWindow:
    return make_window(np.random.default_rng(5), 5.0, 0.15, 50.0, False, 1.0)


def test_reasons_for_windows_without_a_mode(good):
    n = good.speed_t.size
    assert "too few samples" in window_mode(_with(good, speed_t=good.speed_t[:8], speed_rpm=good.speed_rpm[:8]))
    assert window_mode(_with(good, speed_rpm=good.speed_rpm[:-3])) == f"speed has {n} times but {n - 3} values"
    assert "does not leave" in window_mode(_with(good, torque_nm=np.clip(good.torque_nm, -4.0, 4.0)))
    assert "does not leave" in window_mode(_with(good, direction=-1.0))  # the torque goes the other way
    # after the lash closed: the crossing too late for the window
    assert "too few samples after the lash" in window_mode(_with(good, t_cross=float(good.speed_t[-5])))
    rng = np.random.default_rng(0)
    flat = np.round((2000.0 + rng.normal(0, 0.5, n)) / 0.5) * 0.5
    assert "does not follow the torque" in window_mode(_with(good, speed_rpm=flat))
    assert "does not change" in window_mode(_with(good, speed_rpm=np.full(n, 1500.0)))
    # a first-order lag: the speed follows the torque without oscillating
    lag = signal.lsim(([RPM / 0.12], [0.1, 1.0, 0.0]), np.interp(np.arange(0, 1.5, 1e-3), good.torque_t,
                                                                 good.torque_nm), np.arange(0, 1.5, 1e-3))[1]
    slow = 2000.0 + np.interp(good.speed_t, np.arange(0, 1.5, 1e-3), lag) + rng.normal(0, 0.5, n)
    assert "no oscillatory pole pair" in window_mode(_with(good, speed_rpm=slow))
    for period in (1e-9, 1.0):  # a speed period the stamps do not bear out
        assert "does not fit" in window_mode(good, period_s=period)
    lost = (good.speed_t < 0.8) | (good.speed_t > 0.9)  # five 20 ms frames lost after the lash closed: a 120 ms hole
    assert "a gap of 120 ms" in window_mode(_with(good, speed_t=good.speed_t[lost], speed_rpm=good.speed_rpm[lost]))
    nan = good.speed_rpm.copy()
    nan[::7] = np.nan  # invalid frames are dropped, the rest still gives the mode
    m = window_mode(_with(good, speed_rpm=nan))
    assert not isinstance(m, str) and m.freq_hz == pytest.approx(5.0, rel=0.05)


def test_no_mode_anywhere_is_insufficient_data(good):
    flat = _with(good, torque_nm=np.zeros(good.torque_t.size))
    with pytest.raises(InsufficientDataError) as err:
        estimate_modes([flat, flat])
    assert err.value.code == "insufficient_data" and str(err.value).startswith("none of the 2 event windows")
    assert "does not leave" in str(err.value)
    with pytest.raises(InsufficientDataError):
        pooled_mode([])
    with pytest.raises(InputError) as bad_level:
        pooled_mode([window_mode(good)], level=1.0)  # type: ignore[list-item]
    assert bad_level.value.code == "invalid_input"
    assert isinstance(estimate_modes([good, flat]), ModalEstimate)


def test_a_real_capture_without_driving_is_insufficient_data():
    """A real Hyundai Kona EV P-CAN capture (stationary: power off, on, ready, off) has no torque reversal."""
    log = shared_file("kona-ev", "230112-7-2019-pcan-ccan-power-off-on-ready-off.csv")
    smap = load_signal_map(Path(__file__).resolve().parents[2] / "dbc" / "kona_pcan.map.toml")
    signals, _ = load_signals(log, load_database(shared_file("kona-ev", "dbc", "pcan.dbc")), smap, require=REQUIRED)
    with pytest.raises(InsufficientDataError, match="no event windows") as err:
        modes_from_signals(signals, detect_events(signals, DIAGNOSIS_EVENTS))
    assert err.value.code == "insufficient_data"


@settings(max_examples=60, deadline=None)
@given(n=st.integers(0, 60), m=st.integers(0, 60), t_cross=st.floats(-1.0, 3.0), direction=st.sampled_from([1.0, -1.0]),
       seed=st.integers(0, 2**16), scale=st.sampled_from([0.0, 1e-3, 1.0, 1e3]), holes=st.booleans())
def test_any_input_gives_a_mode_or_a_reason(n, m, t_cross, direction, seed, scale, holes):
    """Random stamps (repeated, unordered, non-finite), values and crossings: never an exception."""
    rng = np.random.default_rng(seed)
    st_, tt = np.sort(rng.uniform(0, 1.5, n)), rng.uniform(0, 1.5, m)
    sv, tv = scale * rng.normal(0, 50, n), scale * rng.normal(0, 50, m)
    if holes and n and m:
        st_[rng.integers(0, n)] = np.nan
        tv[rng.integers(0, m)] = np.inf
        st_[: n // 2] = st_[0]
    out = window_mode(EventWindow(st_, sv, tt, tv, t_cross, direction))
    assert isinstance(out, str) or np.isfinite(out.freq_hz)


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**16), keep=st.floats(0.05, 1.0), shift=st.floats(-0.6, 1.2),
       fs=st.sampled_from([20.0, 50.0, 1000.0]), noise=st.sampled_from([0.0, 5.0, 200.0]))
def test_damaged_windows_give_a_mode_or_a_reason(seed, keep, shift, fs, noise):
    """A real window with frames lost at random, a wrong crossing and noise up to swamping the mode."""
    rng = np.random.default_rng(seed)
    w = make_window(rng, 5.0, 0.15, fs, True, 1.0)
    ks, kt = rng.random(w.speed_t.size) < keep, rng.random(w.torque_t.size) < keep
    out = window_mode(EventWindow(w.speed_t[ks], w.speed_rpm[ks] + rng.normal(0, noise + 1e-9, int(ks.sum())),
                                  w.torque_t[kt], w.torque_nm[kt], w.t_cross + shift, w.direction))
    assert isinstance(out, str) or (np.isfinite(out.freq_hz) and out.freq_ci[0] <= out.freq_ci[1])


# --- the independent generator --------------------------------------------------------------------


def linear_shuffle(car) -> tuple[float, float]:
    """(f Hz, zeta) of the lowest oscillatory eigenvalue pair of the generator's own equations,
    linearised with every contact engaged on the drive flank (central differences of its right-hand side)."""
    x = initial_state(car, 25.0)
    e = 1e-3  # rad of penetration beyond each half clearance: spring and full damper engaged
    aint = -car.i2 * (car.gap_mesh2 / 2 + e)  # mesh 2: -(intermediate)/i2 - case
    ain = car.i1 * (car.gap_mesh1 / 2 + e - aint)  # mesh 1: input/i1 + intermediate
    side = -(car.gap_diff / 2 + e)  # case (0) + pinion (0) - side gear
    mid = side - (car.gap_shaft / 2 + e)  # half-shaft middle, side-gear half
    x[:12] = [ain + car.gap_spline / 2 + e, ain, aint, 0.0, 0.0, side, side, mid, mid, mid - e, mid - e, 0.0]
    params = pack(car)
    jac = np.empty((N_STATE, N_STATE))
    hi, lo = np.empty(N_STATE), np.empty(N_STATE)
    for i in range(N_STATE):
        h = 1e-7 * max(1.0, abs(x[i]))
        step = np.zeros(N_STATE)
        step[i] = h
        _rhs(x + step, 0.0, params, hi)
        _rhs(x - step, 0.0, params, lo)
        jac[:, i] = (hi - lo) / (2 * h)
    lam = np.linalg.eigvals(jac)
    lam = lam[lam.imag > 1e-6]
    first = lam[np.argmin(np.abs(lam))]
    return float(abs(first) / (2 * np.pi)), float(-first.real / abs(first))


def test_shuffle_of_the_independent_generator(tmp_path):
    """A 30 s drive of the paper car, logged at 100 Hz with drops, bursts and quantisation, read through the
    ingest: the pooled mode agrees with the linearisation of the generator's equations."""
    car = nominal_car()
    f_lin, zeta_lin = linear_shuffle(car)
    assert 6.5 <= f_lin <= 9.0  # the paper preset's shuffle
    drive = make_drive(car, BAND_A, np.random.default_rng(11), 30.0)
    write_drive(tmp_path / "d.blf", car, simulate(car, drive.t, drive.torque, drive.speed0_kmh), drive.t,
                drive.torque, np.random.default_rng(2))
    signals = read_log(tmp_path / "d.blf", DBC, MAP)
    events = detect_events(signals, DIAGNOSIS_EVENTS)
    est = modes_from_signals(signals, events)
    assert est.freq_hz == pytest.approx(f_lin, rel=0.05)
    assert est.zeta == pytest.approx(zeta_lin, rel=0.2)
    assert est.n_windows == len(events) and est.n_used >= 10
    assert all(m.fs_hz == pytest.approx(100.0, rel=0.02) for m in est.windows)
    # the events the analysis left out are listed with its reasons, at their crossings
    left_out = {ev.t_cross_s: ev.exclusion for ev in events if not ev.included}
    assert {t: r for t, r in est.rejected if t in left_out} == left_out


def test_a_window_met_again_is_not_searched_again(monkeypatch: pytest.MonkeyPatch) -> None:
    """A sequential design's stages take the previous stage's windows again: the mode of a window already seen (same
    samples, same arguments) is the one found before, with no output-error search; a window that differs in one
    sample, or the same samples asked with another sample period, is searched."""
    import app.identify.modal as modal

    rng = np.random.default_rng(11)
    w = make_window(rng, 5.0, 0.1, 100.0, False, 1.0)
    monkeypatch.setattr(modal, "_MEMO", type(modal._MEMO)())
    searched: list[float] = []
    real = modal._fit

    def counted(*a, **k):  # type: ignore[no-untyped-def]
        searched.append(1.0)
        return real(*a, **k)

    monkeypatch.setattr(modal, "_fit", counted)
    first = window_mode(w)
    n = len(searched)
    assert n > 0 and not isinstance(first, str)
    copy = EventWindow(w.speed_t.copy(), w.speed_rpm.copy(), w.torque_t.copy(), w.torque_nm.copy(), w.t_cross,
                       w.direction)
    assert window_mode(copy) is first and len(searched) == n
    assert window_estimate(w) == first  # the search itself gives the same mode
    moved = w.speed_rpm.copy()
    moved[len(moved) // 2] += 0.5
    other = window_mode(EventWindow(w.speed_t, moved, w.torque_t, w.torque_nm, w.t_cross, w.direction))
    assert len(searched) > 2 * n and other is not first
    window_mode(w, period_s=0.01)
    assert len(searched) > 3 * n - 1
    monkeypatch.setattr(modal, "MEMO_WINDOWS", 2)
    window_mode(EventWindow(w.speed_t, w.speed_rpm + 1.0, w.torque_t, w.torque_nm, w.t_cross, w.direction))
    assert len(modal._MEMO) == 2
