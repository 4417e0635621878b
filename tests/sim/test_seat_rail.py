"""Seat-rail acceleration (sim.seat): the mount reaction against the drive unit's momentum balance, the pitch
against an independent integration, the steady tilt by hand, and None where the model has no mounts."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import signal as sps
from scipy.integrate import solve_ivp

from sim import load_vehicle, simulate
from sim.model import GRAVITY, build_chain
from sim.seat import pitch_moment

DT = 0.001
T = np.arange(0.0, 6.0, 0.01)
TORQUE = np.where(T < 1.0, -30.0, 150.0)  # a tip-in from regeneration, then held
PITCHED = load_vehicle("paper").with_changes({"body_pitch.enabled": True})


@pytest.fixture(scope="module")
def run():  # type: ignore[no-untyped-def]
    return simulate(PITCHED, T, TORQUE, output_dt=DT, interp="linear")


def test_none_without_a_mount_model_or_a_body_pitch() -> None:
    assert simulate(load_vehicle("paper"), T, TORQUE).seat_rail_accel_ms2 is None  # no [body_pitch]
    fixed = PITCHED.with_changes({"housing.enabled": False})
    assert simulate(fixed, T, TORQUE).seat_rail_accel_ms2 is None  # no mounts: the reaction goes nowhere modelled
    assert simulate(PITCHED, T, TORQUE, model="two_inertia").seat_rail_accel_ms2 is None


def test_the_mount_torque_closes_the_drive_units_momentum_balance(run) -> None:  # type: ignore[no-untyped-def]
    """Rotor, gears, differential and housing: the rate of their angular momentum (rotor frame) equals the
    torques from outside, the half-shafts' reaction and the mount's (the motor's torque is internal)."""
    sense = {"rotor": 1.0, "input_shaft": 1.0, "intermediate": -1.0, "differential": 1.0, "side_gears": 1.0,
             "housing": 1.0}  # true turning sense in the rotor's frame: the 27/79 pair reverses, the 20/77 back
    m = build_chain(PITCHED)
    inertia = dict(zip(m.body_names, m.inertia, strict=True))
    momentum = sum(inertia[b] * s * run.body_speeds_rpm[b] * math.pi / 30.0 for b, s in sense.items())
    n = PITCHED.driven_wheels
    tau_shafts = run.coupling_torques["halfshaft1"] * n  # reported per shaft
    tau_mount = -run.coupling_torques["mount"]  # reported on the body's side
    k = (run.t > 0.2) & (run.t < 5.8)
    scale = float(np.max(np.abs(tau_mount[k])))
    assert scale > 2000.0  # the clunk's reaction: well beyond the held 11.3 x 150 N m
    # integral form (the impacts make the momentum's derivative on the output grid a poor check):
    # L(t) - L(0) = integral of the outside torques
    outside = -m.wheel_sense * tau_shafts - tau_mount
    impulse = np.concatenate(([0.0], np.cumsum(0.5 * (outside[1:] + outside[:-1]) * np.diff(run.t))))
    swing = float(np.ptp(momentum))
    assert swing > 1.0  # N m s: the drive unit spins up from regeneration to drive
    # (the trapezoid on the 1 ms grid misses part of an impact shorter than a sample: 0.5 % of the swing here)
    assert np.max(np.abs(momentum - momentum[0] - impulse)) < 0.01 * swing
    # held torque: the mount carries the wheel torque, i T, less what accelerates the drive unit's inertias
    assert -tau_mount[-1] == pytest.approx(PITCHED.ratio * 150.0, rel=0.04)


def test_steady_tilt_by_hand(run) -> None:  # type: ignore[no-untyped-def]
    bp = PITCHED.body_pitch
    k_pitch = bp.inertia * (2 * math.pi * bp.frequency_hz) ** 2
    a = run.vehicle_accel_ms2[-1]
    tau_mount = -run.coupling_torques["mount"][-1]  # reported on the body's side; the wheels turn with the rotor
    moment = tau_mount + (PITCHED.wheel.radius - bp.cg_height) * PITCHED.body.mass * a
    assert moment < 0  # the tip-in lifts the nose (nose down is positive)
    theta = moment / k_pitch
    seat = run.seat_rail_accel_ms2
    assert seat is not None
    assert seat[-1] - a == pytest.approx(-GRAVITY * theta, rel=0.01)  # the sensor tilts back: reads more forward
    assert seat[-1] > a + 0.1
    # quasi-statically the two moments add up to the load transfer -M a h_cg, the road load's moment about the
    # wheel centre (rolling and aero, taken at the centre of gravity) and the wheels' spin-up
    body, wheel = PITCHED.body, PITCHED.wheel
    v = run.vehicle_speed_kmh[-1] / 3.6
    road = body.rolling_resistance * body.mass * GRAVITY + 0.5 * body.air_density * body.drag_area * v**2
    spin_up = PITCHED.driven_wheels * wheel.inertia * a / wheel.radius
    expected = -body.mass * a * bp.cg_height - road * wheel.radius - spin_up
    assert moment == pytest.approx(expected, rel=0.005)  # the rest: the drive unit's own spin-up


def test_pitch_against_an_independent_integration(run) -> None:  # type: ignore[no-untyped-def]
    bp = PITCHED.body_pitch
    m = build_chain(PITCHED)
    moment = pitch_moment(PITCHED, m, run.vehicle_accel_ms2, -run.coupling_torques["mount"])
    wp = 2 * math.pi * bp.frequency_hz
    c, k = 2 * bp.damping_ratio * wp * bp.inertia, wp**2 * bp.inertia

    def rhs(t: float, x: np.ndarray) -> list[float]:
        return [x[1], (float(np.interp(t, run.t, moment)) - c * x[1] - k * x[0]) / bp.inertia]

    sol = solve_ivp(rhs, (run.t[0], run.t[-1]), [moment[0] / k, 0.0], t_eval=run.t, rtol=1e-9, atol=1e-12,
                    max_step=DT)
    theta, rate = sol.y
    acc = (moment - c * rate - k * theta) / bp.inertia
    seat = run.vehicle_accel_ms2 + (bp.seat_rail_height - bp.cg_height) * acc - GRAVITY * theta
    assert run.seat_rail_accel_ms2 is not None
    err = np.abs(run.seat_rail_accel_ms2 - seat)
    assert np.max(err[run.t > 1.2]) < 0.01  # m/s^2; the shuffle swings by ~5 m/s^2 peak to peak
    assert np.median(err) < 1e-3


def test_at_the_shuffle_the_rail_swings_with_the_pitch_moment_over_the_pitch_inertia(run) -> None:  # type: ignore[no-untyped-def]
    """Far above the ~1.3 Hz pitch mode the body's pitch is inertia-bound: theta'' ~ M_y / I (times
    1 / (1 - (f_p / f)^2) = 1.03 at the 7.6 Hz shuffle). Two seat-rail heights give theta'' as the difference of
    their readings over the difference of the heights."""
    bp = PITCHED.body_pitch
    at_cg = simulate(PITCHED.with_changes({"body_pitch.seat_rail_height": bp.cg_height}), T, TORQUE, output_dt=DT,
                     interp="linear")
    assert run.seat_rail_accel_ms2 is not None and at_cg.seat_rail_accel_ms2 is not None
    pitch_acc = (run.seat_rail_accel_ms2 - at_cg.seat_rail_accel_ms2) / (bp.seat_rail_height - bp.cg_height)
    moment = pitch_moment(PITCHED, build_chain(PITCHED), run.vehicle_accel_ms2, -run.coupling_torques["mount"])
    sos = sps.butter(2, (4.0, 15.0), "band", fs=1.0 / DT, output="sos")  # the shuffle band
    w = (run.t > 1.1) & (run.t < 2.5)
    got = np.ptp(sps.sosfiltfilt(sos, pitch_acc)[w])
    by_hand = np.ptp(sps.sosfiltfilt(sos, moment / bp.inertia)[w])
    assert got / by_hand == pytest.approx(1.03, abs=0.03)
    # 0.25 m below the centre of gravity that is a tenth of the body's shuffle on top
    body_pp = np.ptp(run.vehicle_accel_ms2[w])
    assert 0.05 * body_pp < 0.25 * got < 0.2 * body_pp
