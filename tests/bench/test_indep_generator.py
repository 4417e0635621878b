"""The independent validation generator (bench/indep): import rule, physics with values, BLF round trip.

No diagnosis outcome is asserted on generator cases: they judge the diagnosis, they do not tune it.
"""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from bench.indep.car import G, nominal_car, ratio, with_effect
from bench.indep.drive import BAND_A, make_drive
from bench.indep.dynamics import DT, actuator, simulate
from bench.indep.record import DBC, MAP, RPM, Recording, sensor_speed, write_drive

ROOT = Path(__file__).resolve().parents[2] / "bench" / "indep"
CAR = nominal_car()
V_KMH = 25.0


def _hold_nm(car=CAR, v_kmh: float = V_KMH) -> float:
    v = v_kmh / 3.6
    return (car.crr * car.mass * G + 0.5 * car.rho * car.cda * v * v) * car.radius / ratio(car)


def _run(car, torque_fn, duration: float = 3.0, v_kmh: float = V_KMH):
    t = np.arange(round(duration / DT) + 1) * DT
    tq = torque_fn(t)
    return t, tq, simulate(car, t, tq, v_kmh)


def _step(lo: float, hi: float, at: float = 0.5, ramp: float = 0.01):
    return lambda t: lo + (hi - lo) * np.clip((t - at) / ramp, 0, 1)


def _freq(t: np.ndarray, y: np.ndarray, t0: float, t1: float) -> float:
    """Dominant oscillation frequency (Hz) of ``y`` on [t0, t1] from its detrended zero crossings."""
    m = (t >= t0) & (t <= t1)
    yy = y[m] - np.polyval(np.polyfit(t[m], y[m], 2), t[m])
    s = np.signbit(yy)
    cross = t[m][1:][s[1:] != s[:-1]]
    return float((cross.size - 1) / 2 / (cross[-1] - cross[0]))


def test_generator_imports_neither_sim_nor_app():
    files = [*sorted(ROOT.glob("*.py")), ROOT.parent / "diagnosis_indep.py"]
    for f in files[:-1]:
        tree = ast.parse(f.read_text(encoding="utf-8"))
        names = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
        names |= {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        bad = {n for n in names if n.split(".")[0] in ("sim", "app")}
        assert not bad, f"{f.name} imports {bad}"
    assert len(files) >= 7  # the package's modules were found


def test_nominal_car_is_the_paper_preset():
    assert CAR.i1 * CAR.i2 == pytest.approx(79 / 27 * 77 / 20)
    assert (CAR.gap_spline, CAR.gap_diff, CAR.gap_shaft) == (0.014, 0.006, 0.024)
    assert CAR.k_shaft_l == CAR.k_shaft_r == 8000.0


def test_quasi_static_ratio_and_equal_wheels():
    _t, _, o = _run(CAR, lambda t: np.full(t.size, _hold_nm()), 2.0)
    wheel = 0.5 * (o["wheel_l"] + o["wheel_r"])
    assert np.median(o["speed_rel"][-200:] / wheel[-200:]) == pytest.approx(ratio(CAR), rel=1e-4)
    assert wheel[-1] * CAR.radius * 3.6 == pytest.approx(V_KMH, abs=0.3)  # road load held: speed constant
    # a drive with reversals: equal half-shafts, so both wheels turn alike
    d = make_drive(CAR, BAND_A, np.random.default_rng(5), 6.0)
    o = simulate(CAR, d.t, d.torque, d.speed0_kmh)
    assert np.max(np.abs(o["wheel_l"] - o["wheel_r"])) < 1e-9
    uneq = with_effect(CAR, "unequal_shafts", {"left_scale": 0.5, "right_scale": 1.2})
    o2 = simulate(uneq, d.t, d.torque, d.speed0_kmh)
    # the open differential lets them differ: the softer shaft winds up further, its wheel lags in transients
    assert np.max(np.abs(o2["wheel_l"] - o2["wheel_r"])) > 2e-3  # rad/s (stiff tyres tie both to the road: 3.6e-3)
    loaded = d.torque[::5][: o2["t"].size] > 30.0
    assert np.mean((o2["d_shaft_l"] - o2["d_shaft_r"])[loaded]) > 3e-3  # rad: 0.5x vs 1.2x shaft stiffness


def test_steady_state_gap_positions():
    tq = 40.0  # N m drive, the car accelerates gently: contact loads follow the static torque flow within 5 %
    _, _, o = _run(CAR, lambda t: np.full(t.size, tq), 1.5)
    i1, ig = CAR.i1, ratio(CAR)
    m_eff_share = 1 - (CAR.j_rotor * ig**2) / (CAR.j_rotor * ig**2 + CAR.mass * CAR.radius**2)  # of the torque
    expect = {"d_spline": CAR.gap_spline / 2 + tq * m_eff_share / CAR.k_spline,
              "d_mesh1": CAR.gap_mesh1 / 2 + tq * i1 * m_eff_share / CAR.k_mesh1,
              "d_mesh2": CAR.gap_mesh2 / 2 + tq * ig * m_eff_share / CAR.k_mesh2,
              "d_diff_l": CAR.gap_diff / 2 + tq * ig / 2 * m_eff_share / CAR.k_diff,
              "d_shaft_l": CAR.gap_shaft / 2 + tq * ig / 2 * m_eff_share / (2 * CAR.k_shaft_l)}
    for k, v in expect.items():
        got = float(np.mean(o[k][-400:]))
        gap = (v - _gap(k)) / 1
        assert got - _gap(k) == pytest.approx(gap, rel=0.05), k
    # housing roll carries minus the output torque on its mounts
    assert np.mean(o["housing"][-400:]) == pytest.approx(-tq * ig * m_eff_share / CAR.k_mount, rel=0.05)
    # coasting: every contact on the other flank
    _, _, o = _run(CAR, lambda t: np.full(t.size, -20.0), 1.5)
    for k in expect:
        assert np.mean(o[k][-400:]) < -_gap(k)


def _gap(col: str) -> float:
    return {"d_spline": CAR.gap_spline, "d_mesh1": CAR.gap_mesh1, "d_mesh2": CAR.gap_mesh2,
            "d_diff_l": CAR.gap_diff, "d_shaft_l": CAR.gap_shaft}[col] / 2


def _shuffle_hz(car) -> float:
    _t, _, o = _run(car, _step(20.0, 60.0), 2.5)
    twist = o["speed_rel"] / ratio(car) - 0.5 * (o["wheel_l"] + o["wheel_r"])
    return _freq(o["t"], twist, 0.55, 1.6)


def test_shuffle_frequency_and_tyre_and_hardening_knobs():
    f0 = _shuffle_hz(CAR)
    assert 6.5 <= f0 <= 9.0  # the paper preset's shuffle is ~7-8 Hz
    soft_tyre = with_effect(CAR, "tyre_slip", {"c_n": 3.0e4, "sigma_m": 0.4})
    assert _shuffle_hz(soft_tyre) < 0.9 * f0
    hard = with_effect(CAR, "progressive_stiffness", {"shaft_rel": 2.0, "mount_rel": 0.0})
    assert _shuffle_hz(hard) > 1.03 * f0


def test_actuator_and_sensor_knobs():
    t = np.arange(0, 0.3, DT)
    step = (t >= 0.05).astype(float) * 100.0
    lag = with_effect(CAR, "torque_lag", {"tau_s": 0.02, "dead_s": 0.01})
    y = actuator(lag, t, step)
    assert np.interp(0.0599, t, y) == pytest.approx(0.0, abs=1e-9)  # dead time
    assert np.interp(0.08, t, y) == pytest.approx(100 * (1 - np.exp(-1)), rel=0.01)  # one tau after
    assert np.array_equal(actuator(CAR, t, step), step)
    ramp = t * 1000.0  # rad/s rising 1000 rad/s^2
    slow = with_effect(CAR, "speed_sensor", {"window_s": 0.02, "delay_s": 0.005})
    lagged = (ramp[-1] - sensor_speed(slow, t, ramp)[-1] / RPM) / 1000.0
    assert lagged == pytest.approx(0.005 + (0.02 - DT) / 2, abs=2e-4)  # a window lags by half its length
    assert (ramp[-1] - sensor_speed(CAR, t, ramp)[-1] / RPM) / 1000.0 == pytest.approx((0.002 - DT) / 2, abs=1e-6)


def test_drag_mount_and_backlash_knobs():
    coast = lambda t: np.zeros(t.size)  # noqa: E731
    _, _, o = _run(CAR, coast, 1.0)
    dragged = with_effect(CAR, "drag", {"coulomb_nm": 5.0, "viscous_nms": 0.0})
    _, _, od = _run(dragged, coast, 1.0)
    dec = (o["body_v"][0] - o["body_v"][-1]) - (od["body_v"][0] - od["body_v"][-1])
    ig = ratio(CAR)
    m_eff = CAR.mass + 2 * CAR.j_wheel / CAR.radius**2 + (CAR.j_rotor + 0.01) * ig**2 / CAR.radius**2
    assert -dec == pytest.approx(5.0 * ig / CAR.radius / m_eff * 1.0, rel=0.1)  # m/s lost in 1 s to 5 N m
    soft = with_effect(CAR, "housing_mount", {"k_scale": 0.5, "c_scale": 1.0})
    _, _, oh = _run(soft, lambda t: np.full(t.size, _hold_nm()), 1.5)
    assert np.mean(oh["housing"][-400:]) == pytest.approx(-_hold_nm() * ig / (0.5 * CAR.k_mount), rel=0.05)
    wide = with_effect(CAR, "backlash", {"diff_scale": 2.0, "shaft_scale": 1.5, "mesh_scale": 1.0})
    tip = _step(-20.0, 40.0, at=0.5, ramp=0.05)
    _, _, a = _run(CAR, tip, 2.0)
    _, _, b = _run(wide, tip, 2.0)

    def travel(run, col):  # flank to flank: settled before the tip-in to settled after it (same loads)
        before = (run["t"] > 0.35) & (run["t"] < 0.45)
        return float(np.mean(run[col][-300:]) - np.mean(run[col][before]))

    assert travel(b, "d_diff_l") - travel(a, "d_diff_l") == pytest.approx(CAR.gap_diff, rel=0.05)
    assert travel(b, "d_shaft_l") - travel(a, "d_shaft_l") == pytest.approx(0.5 * CAR.gap_shaft, rel=0.05)
    assert travel(b, "d_spline") - travel(a, "d_spline") == pytest.approx(0.0, abs=0.05 * CAR.gap_spline)


def test_short_drive_reads_back_through_lashscope_ingest(tmp_path):
    from tests.support.truthlog import read_log

    d = make_drive(CAR, BAND_A, np.random.default_rng(11), 10.0)
    o = simulate(CAR, d.t, d.torque, d.speed0_kmh)
    rec = Recording(speed_noise_rpm=0.0, torque_noise_nm=0.0, wheel_noise_rpm=0.0, jitter_s=0.0, drop_fraction=0.0,
                    sna_fraction=0.0, max_offset_s=0.0, drop_runs_per_min=0.0, bursts_per_min=0.0)
    info = write_drive(tmp_path / "a.blf", CAR, o, d.t, d.torque, np.random.default_rng(2), rec)
    s = read_log(tmp_path / "a.blf", DBC, MAP)
    tq, sp = s["motor_torque_nm"], s["motor_speed_rpm"]
    assert 990 <= tq.t.size <= 1000 and 990 <= sp.t.size <= 1000  # 10 ms frames, none dropped
    t0 = _log_start(info["first_s"])
    assert np.max(np.abs(tq.values - np.interp(tq.t + t0, d.t, d.torque))) <= 0.05 + 1e-3  # 0.1 N m steps
    ref = np.interp(sp.t + t0, o["t"], sensor_speed(CAR, o["t"], o["speed_rel"]))
    assert np.max(np.abs(sp.values - ref)) <= 0.25 + 1e-2  # 0.5 rpm steps
    # the realistic recording: SNA frames become NaN, drops thin the frames
    write_drive(tmp_path / "b.blf", CAR, o, d.t, d.torque, np.random.default_rng(3),
                Recording(sna_fraction=0.01, drop_fraction=0.05))
    s2 = read_log(tmp_path / "b.blf", DBC, MAP)
    n_nan = int(np.isnan(s2["motor_speed_rpm"].values).sum() + np.isnan(s2["motor_torque_nm"].values).sum())
    assert 2 <= n_nan <= 60
    assert s2["motor_speed_rpm"].t.size < 960


def _log_start(first_s: float) -> float:
    """Generator time of the ingest's zero: the first logged frame's time, to the millisecond below."""
    return float(np.floor(first_s * 1000.0) / 1000.0)


def test_signal_size_and_manifest_round_trip(tmp_path):
    from bench.indep.cases import NOISE_RPM, Case, read_manifest, signal_sigma, truth_car, write_manifest

    d = make_drive(CAR, BAND_A, np.random.default_rng(8), 6.0)
    assert pytest.approx(np.hypot(0.5, 0.5 / np.sqrt(12))) == NOISE_RPM
    assert signal_sigma(truth_car({}), d) == 0.0
    slow = signal_sigma(truth_car({"speed_sensor": {"window_s": 0.02, "delay_s": 0.0}}), d)
    slower = signal_sigma(truth_car({"speed_sensor": {"window_s": 0.03, "delay_s": 0.005}}), d)
    assert 2.0 < slow < slower
    cases = [Case("none_1", "none", 1, {}, ["none"], 6.0, drive_a="none_1_A.blf", drive_b="none_1_B.blf")]
    write_manifest(tmp_path / "m.json", cases)
    assert read_manifest(tmp_path / "m.json") == cases
    (tmp_path / "old.json").write_text('{"generator": "0", "cases": []}', encoding="utf-8")
    assert read_manifest(tmp_path / "old.json") == []  # made by another generator version: not reused


def test_window_ms_on_stretches_equals_it_on_the_whole_drive():
    """Each window is interpolated on the stretch of the drive around it; the mean square is the one the whole
    drive's table gives, number for number (windows near both ends included)."""
    from bench.indep.cases import SHIFT_S, _reported, truth_car, window_ms

    d = make_drive(CAR, BAND_A, np.random.default_rng(5), 20.0)
    t, a = _reported(CAR, d)
    _, b = _reported(truth_car({"torque_lag": {"tau_s": 0.012, "dead_s": 0.0}}), d)
    assert d.reversals.size >= 6
    grids = [g for r in d.reversals
             if (g := np.arange(r - 0.2, r + 1.0, 0.01))[0] > SHIFT_S and g[-1] < t[-1] - SHIFT_S]

    def whole(shift: float) -> float:
        parts = []
        for g in grids:
            e = np.interp(g - shift, t, b) - np.interp(g, t, a)
            parts.append(e - np.polyval(np.polyfit(g, e, 1), g))
        e = np.concatenate(parts)
        return float(np.mean(e * e))

    expected = min(whole(float(s)) for s in np.arange(-SHIFT_S, SHIFT_S + 1e-9, 0.0005))
    assert expected > 0.0
    assert window_ms(t, a, b, d) == expected


def test_second_channel_signature_adds_the_wheels_only_where_they_differ():
    from bench.indep.cases import signal_sigma, truth_car
    from bench.separable import channels, two_channel_sigma

    d = make_drive(CAR, BAND_A, np.random.default_rng(8), 6.0)
    nominal = channels(truth_car({}), d)
    assert two_channel_sigma(nominal, nominal, d) == 0.0
    # a speed-sensor filter changes the inverter's reading, not the wheels: the second channel adds nothing
    filt = truth_car({"speed_sensor": {"window_s": 0.02, "delay_s": 0.0}})
    assert two_channel_sigma(channels(filt, d), nominal, d) == pytest.approx(signal_sigma(filt, d), rel=1e-9)
    # a heavier car moves the wheels too: both channels see it (the wheels at a tenth of the motor speed and 0.2 rpm
    # of noise add little: 10.6 against 10.4 sigma here)
    heavy = truth_car({}, {"mass_scale": 1.2})
    alone = signal_sigma(heavy, d)
    assert two_channel_sigma(channels(heavy, d), nominal, d) > 1.01 * alone > 0.0


def _paper_speed(t: np.ndarray, tq: np.ndarray, speed0_rpm: float, t_out: np.ndarray) -> np.ndarray:
    from sim import load_vehicle
    from sim import simulate as sim_simulate

    res = sim_simulate(load_vehicle("paper"), t[::10], tq[::10], model="multibody", speed0_rpm=speed0_rpm,
                       interp="linear", output_dt=0.0005)
    return np.asarray(np.interp(t_out, np.asarray(res.t), np.asarray(res.motor_speed_rpm)))


def test_nominal_car_lies_in_the_paper_models_family():
    """A "no effect" case must be one: on a sharp tip-in (-30 -> 100 N m, 1200 N m/s, 200 N m/s through the
    lash) the nominal car and the paper preset differ by well under a rpm once a line is removed, while a real
    tyre (the ``tyre_slip`` case) differs by tens of rpm. The first nominal tyre (2 MN per unit slip) left
    3 rpm RMS, 5x the benchmark's noise: a faint tyre effect on every "no effect" drive."""
    def tq(t: np.ndarray) -> np.ndarray:
        ramp = np.clip(-30 + 1200 * (t - 1.0), -30, 100)
        t_lash = 1.0 + 20 / 1200
        slow = np.clip(-10 + 200 * (t - t_lash), -10, 10)
        out = np.where((ramp > -10) & (ramp < 10) & (t > 1.0), slow, ramp)
        return np.where(t > t_lash + 0.1, np.minimum(10 + 1200 * (t - t_lash - 0.1), 100), out)

    def gap(car) -> float:
        t, torque, out = _run(car, tq, duration=3.0)
        rpm = out["speed_rel"] * RPM
        ours = _paper_speed(t, torque, float(rpm[0]), out["t"])
        m = out["t"] > 0.9
        d = rpm[m] - ours[m]
        d = d - np.polyval(np.polyfit(out["t"][m], d, 1), out["t"][m])
        return float(np.sqrt(np.mean(d * d)))

    nominal = gap(CAR)
    real_tyre = gap(with_effect(CAR, "tyre_slip", {"c_n": 8.0e4, "sigma_m": 0.3}))
    assert nominal < 1.2  # rpm; 0.8 measured
    assert real_tyre > 10 * nominal


def test_chain_car_is_the_chain_drive_preset_and_its_mode_is_the_presets():
    from bench.indep.car import chain_car
    from bench.indep.dynamics import first_mode, substeps
    from sim import load_vehicle
    from sim.linear import modal_frequencies_hz
    from sim.model import build_chain

    chain = chain_car()
    assert ratio(chain) == pytest.approx(42 / 11)
    assert (chain.mass, chain.k_shaft_l, chain.gap_mesh1, chain.gap_mesh2) == (300.0, 4000.0, 0.019, 0.0)
    for car, preset in ((CAR, "paper"), (chain, "chain_drive")):
        theirs = modal_frequencies_hz(build_chain(load_vehicle(preset)))[1]
        # same physical car, other equations: the chain car's stiff sprocket-case joint adds ~1 % compliance
        assert first_mode(car)[0] == pytest.approx(theirs, rel=0.01), preset
        assert substeps(car) == 1  # the nominal cars integrate at the plain step


def test_base_parameter_truths():
    from bench.indep.car import lash_at_motor_mrad, stiffness_at_motor, with_base

    k0, lash0 = stiffness_at_motor(CAR), lash_at_motor_mrad(CAR)
    ig = ratio(CAR)
    assert lash0 == pytest.approx(1e3 * (0.014 + 79 / 27 * 0.0026 + ig * (0.0012 + 0.006 + 0.024)))
    shafts_share = ig**2 / (2 * CAR.k_shaft_l) * k0  # the half-shafts: ~89 % of the compliance at the motor
    assert 0.88 < shafts_share < 0.9
    soft = with_base(CAR, {"k_scale": 0.7})
    expect = 1 / (1 - shafts_share + shafts_share / 0.7)
    assert stiffness_at_motor(soft) / k0 == pytest.approx(expect)
    assert 0.72 < expect < 0.73  # near 0.7x: the shafts dominate
    assert lash_at_motor_mrad(with_base(CAR, {"gap_scale": 1.4})) == pytest.approx(1.4 * lash0)
    heavy = with_base(CAR, {"mass_scale": 1.2, "c_scale": 2.0})
    assert (heavy.mass, heavy.c_shaft_r, heavy.c_mesh2, heavy.c_mount) == (2100.0, 50.0, 120.0, CAR.c_mount)
    assert stiffness_at_motor(heavy) == k0


def _fitted_mode(car, lo: float, hi: float) -> tuple[float, float]:
    """(damped frequency Hz, damping ratio) of the twist ringing after a 5 ms step, by a plain damped-cosine fit."""
    from scipy.optimize import curve_fit

    _t, _, o = _run(car, _step(lo, hi, ramp=0.005), 2.0, v_kmh=30.0)
    twist = o["speed_rel"] / ratio(car) - 0.5 * (o["wheel_l"] + o["wheel_r"])
    m = (o["t"] > 0.51) & (o["t"] < 1.5)
    tt, y = o["t"][m] - 0.51, twist[m]

    def model(t, a, s, w, p, c0, c1):
        return a * np.exp(-s * t) * np.cos(w * t + p) + c0 + c1 * t

    w0 = 2 * np.pi * _freq(o["t"], twist, 0.51, 1.0)  # zero crossings start the fit
    p, _ = curve_fit(model, tt, y, p0=[np.ptp(y) / 2, 0.1 * w0, w0, 0.0, float(y.mean()), 0.0], maxfev=20000)
    return abs(p[2]) / (2 * np.pi), p[1] / np.hypot(p[1], p[2])


@pytest.mark.parametrize("which", ["paper", "paper_soft_damped", "chain_heavily_damped"])
def test_linearised_mode_is_the_mode_of_a_simulated_tip_in(which):
    from bench.indep.car import chain_car, with_base
    from bench.indep.dynamics import first_mode

    car, lo, hi = {"paper": (CAR, 20.0, 60.0),
                   "paper_soft_damped": (with_base(CAR, {"k_scale": 0.7, "c_scale": 2.5}), 20.0, 60.0),
                   "chain_heavily_damped": (with_base(chain_car(), {"c_scale": 8.0}), 10.0, 40.0)}[which]
    fn, zeta, fd = first_mode(car, 30.0)
    f_fit, z_fit = _fitted_mode(car, lo, hi)
    assert f_fit == pytest.approx(fd, rel=0.005)
    assert z_fit == pytest.approx(zeta, rel=0.02)
    assert fn == pytest.approx(fd / np.sqrt(1 - zeta**2))
    if which == "chain_heavily_damped":
        assert 0.2 < zeta < 0.35  # the heavily damped chain car of the identification sets


def test_identification_cases_and_their_truths(tmp_path):
    from bench.indep.cases import CHAIN_ZETA, build, plan, recording

    cases = plan("idev", True)
    kinds = {c.kind for c in cases}
    assert kinds == {"none", "base", "base_effect"}
    chain = [c for c in cases if c.car == "chain_drive"]
    assert chain and all(c.rate_hz <= 50 and recording(c).bursts_per_min > 4 for c in chain)
    assert [c.moved() for c in cases if c.kind == "base" and c.car == "paper"] == [
        ["stiffness"], ["damping_ratio"], ["mass"], ["lash"]]
    assert recording(plan("dev", True)[0]) == Recording()  # the old sets keep their logger
    assert {recording(c).period_s for c in cases if c.car == "paper"} == {0.01, 0.001}
    c = next(c for c in chain if c.kind == "base")
    c.duration_s = 4.0  # a short drive: only the truths and the recording are checked here
    build(c, tmp_path)
    tr = c.truth
    assert CHAIN_ZETA[0] < tr["zeta"] < CHAIN_ZETA[1]
    assert tr["zeta_nominal"] < 0.05 and 14 < tr["freq_hz_nominal"] < 17
    assert tr["mass_nominal"] == 300.0 and tr["stiffness_nominal"] == pytest.approx(371.6, rel=1e-3)
    assert (tmp_path / c.drive_a).exists() and (tmp_path / c.drive_b).exists()


def test_low_mode_chain_car_is_its_file_on_both_sides(tmp_path):
    """The low-mode chain car (bench/indep/chain_low.toml): the generator and lashscope read the same file and find
    the same 5.5 Hz first mode; its sets plan it, slow and bursty, damped to the drawn ratio."""
    from app.identify.base import physical
    from bench.indep.car import CHAIN_LOW, car_named, vehicle_source
    from bench.indep.cases import CHAIN_LOW_ZETA, build, plan, recording
    from bench.indep.dynamics import first_mode
    from sim import load_vehicle

    ours = physical(load_vehicle(vehicle_source("chain_low")))
    fn, zeta, _ = first_mode(car_named("chain_low"))
    assert 5.3 < fn < 5.7 and 0.17 < zeta < 0.21
    assert ours.freq_hz == pytest.approx(fn, rel=0.01) and ours.damping_ratio == pytest.approx(zeta, rel=0.02)
    assert car_named("chain_low").k_shaft_l == 350.0 and vehicle_source("chain_low") == str(CHAIN_LOW)
    assert vehicle_source("paper") == "paper"
    with pytest.raises(ValueError, match="chain_low"):
        vehicle_source("tractor")
    cases = plan("idev2", True)
    chain = [c for c in cases if c.car.startswith("chain")]
    assert chain and {c.car for c in chain} == {"chain_low"}
    assert all(c.rate_hz <= 50 and recording(c).bursts_per_min > 4 for c in chain)
    assert {c.car for c in plan("idev", True) if c.car.startswith("chain")} == {"chain_drive"}  # the old sets stay
    c = next(c for c in chain if c.kind == "base")
    c.duration_s = 4.0
    build(c, tmp_path)
    assert CHAIN_LOW_ZETA[0] < c.truth["zeta"] < CHAIN_LOW_ZETA[1]
    assert 5.3 < c.truth["freq_hz_nominal"] < 5.7
