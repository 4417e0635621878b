"""The rigid-body inertia of whole drives (``app/identify/rigid.py``) and where it sets the mass."""

from __future__ import annotations

import numpy as np
import pytest

from app.analysis.diagnosis.calibrate import FitResult
from app.analysis.diagnosis.forward import Nuisance
from app.analysis.diagnosis.uncertainty import rigid_inertia
from app.identify.base import BASE_EFFECTS, with_base
from app.identify.fit import RIGID_FORM, rigid_fill, rigid_pin
from app.identify.rigid import RigidBody, rigid_body
from app.signals import Interp, Signal, SignalSet
from sim import load_vehicle
from tests.identify.drives import drive_signals


@pytest.mark.parametrize(("vehicle", "truth", "gain"), [("paper", {}, 1.0), ("paper", {"mass": 1.2}, 1.0),
                                                        ("chain_drive", {"mass": 0.85, "stiffness": 0.7}, 0.8)])
def test_the_inertia_per_logged_newton_metre_is_read_from_whole_drives(vehicle: str, truth: dict[str, float],
                                                                       gain: float) -> None:
    """Drives of lashscope's own simulator with a known mass and torque gain: the figure is the truth's rigid
    inertia over its gain within 3 %, its interval holds it, and the file's figure is outside when they differ."""
    nominal = load_vehicle(vehicle)
    car = with_base(nominal, truth).with_changes({"motor.torque_gain": gain})
    signals = drive_signals({}, 11, duration_s=60.0, vehicle=vehicle) if not truth and gain == 1.0 else None
    if signals is None:
        from tests.support.synthetic import CanSampling, DriveSpec, make_drive, measure, run_truth, to_signals

        rng = np.random.default_rng(11)
        drive = make_drive(nominal, rng, DriveSpec(duration_s=60.0))
        signals = to_signals(measure(drive, run_truth(car, drive), CanSampling(period_s=0.01), rng))
    rb = rigid_body([signals], nominal)
    expected = rigid_inertia(car) / gain
    assert rb.inertia_kgm2 == pytest.approx(expected, rel=0.03) and rb.r2 is not None and rb.r2 > 0.9
    assert rb.ci is not None and rb.ci[0] <= expected * 1.01 and expected * 0.99 <= rb.ci[1]
    assert rb.file_inertia_kgm2 == pytest.approx(rigid_inertia(nominal))
    assert rb.off_the_file is (car != nominal)  # a right file is inside the interval, a 7 % change is not
    if rb.off_the_file:
        assert "the logs cannot tell these apart" in rb.describe()


def test_braked_stretches_do_not_count() -> None:
    """The friction brakes decelerate whatever the torque: braking against the drive (left-foot braking) in the
    speed channel, with a brake pressure channel resting at 10 psi, reads the inertia of the drive without those
    stretches; without the channel the braked stretches make the car look heavier."""
    nominal = load_vehicle("paper")
    clean = drive_signals({}, 12, duration_s=60.0)
    speed = clean["motor_speed_rpm"]
    t = speed.t
    # braking against the drive (left-foot braking): 3 s of every 12, where the torque drives
    braked = ((t % 12.0) > 9.0) & (clean["motor_torque_nm"].at(t) > 20.0)
    # the brakes take away speed at 500 rpm/s while they act (and keep it away after)
    lost = np.cumsum(np.where(braked, 500.0, 0.0) * np.gradient(t))
    slowed = SignalSet({**clean.signals, "motor_speed_rpm": Signal.from_samples(
        "motor_speed_rpm", t, speed.values - lost, "rpm")})
    without_channel = rigid_body([slowed], nominal)
    slowed.add(Signal.from_samples("brake", t, np.where(braked, 400.0, 10.0), "psi", Interp.PREVIOUS))
    with_channel = rigid_body([slowed], nominal)
    reference = rigid_body([clean], nominal)
    assert with_channel.inertia_kgm2 == pytest.approx(reference.inertia_kgm2, rel=0.03)
    assert without_channel.inertia_kgm2 is None or abs(without_channel.inertia_kgm2 /
                                                       reference.inertia_kgm2 - 1.0) > 0.1
    assert with_channel.driving_s < 0.85 * reference.driving_s


def test_too_little_driving_or_no_response_is_no_estimate() -> None:
    nominal = load_vehicle("paper")
    short = drive_signals({}, 13, duration_s=8.0)
    rb = rigid_body([short], nominal)
    assert rb.inertia_kgm2 is None and "under 10 s" in rb.reason and "no estimate" in rb.describe()
    s = drive_signals({}, 14, duration_s=40.0)
    flat = SignalSet({**s.signals, "motor_speed_rpm": Signal.from_samples(
        "motor_speed_rpm", s["motor_speed_rpm"].t, np.full(len(s["motor_speed_rpm"]), 2000.0)
        + np.random.default_rng(0).normal(0, 3.0, len(s["motor_speed_rpm"])), "rpm")})
    rb = rigid_body([flat], nominal)
    assert rb.inertia_kgm2 is None and "does not follow the logged torque" in rb.reason


def _joint(mass_scale: float, gain: float) -> FitResult:
    spec = BASE_EFFECTS["mass"].params[0]
    return FitResult(effects=(BASE_EFFECTS["mass"].id,), nuisance=Nuisance(0.0, gain, 0.0),
                     values={BASE_EFFECTS["mass"].id: {spec.name: mass_scale}}, chi2=1.0, n=100, nfev=1)


def test_the_mass_is_set_from_the_rigid_body_only_where_the_windows_stray() -> None:
    """The windows' mass 1.66x with gain 0.85 puts the rigid inertia at ~1.9x the file's; whole drives that read
    1.45x [1.40, 1.50] set the mass at the scale that gives 1.45x with the file's gain, with the model-form floor in
    its half-width. A windows' fit within 25 % of the drives' figure, or a wide interval, leaves the mass alone."""
    v = load_vehicle("chain_drive")
    j0 = rigid_inertia(v)
    drives = RigidBody(1.45 * j0, (1.40 * j0, 1.50 * j0), j0, 120.0, 0.9)
    pinned = rigid_pin(v, ["stiffness", "mass"], _joint(1.66, 0.85), drives)
    assert pinned is not None
    ratio, half, why = pinned
    assert rigid_inertia(with_base(v, {"mass": ratio})) == pytest.approx(1.45 * j0, rel=1e-6)
    assert half == pytest.approx(np.hypot(0.5 * np.log(1.50 / 1.40), np.log1p(RIGID_FORM)))
    assert "cannot tell these apart" in why and "1.66x" in why
    assert rigid_pin(v, ["stiffness", "mass"], _joint(1.40, 1.0), drives) is None  # within 25 %
    assert rigid_pin(v, ["stiffness"], _joint(1.66, 0.85), drives) is None  # the mass is not fitted
    wide = RigidBody(1.45 * j0, (1.0 * j0, 2.0 * j0), j0, 20.0, 0.6)
    assert rigid_pin(v, ["stiffness", "mass"], _joint(0.6, 1.1), wide) is None


def test_a_mass_the_windows_cannot_pin_comes_from_a_clear_rigid_body_off_the_file() -> None:
    """Too few events to pin the mass: a clear whole-drives figure off the file sets it; one that holds the file's
    value, or a wide one, leaves the mass at the file's."""
    v = load_vehicle("chain_drive")
    j0 = rigid_inertia(v)
    filled = rigid_fill(v, RigidBody(1.4 * j0, (1.3 * j0, 1.5 * j0), j0, 90.0, 0.9))
    assert filled is not None and rigid_inertia(with_base(v, {"mass": filled[0]})) == pytest.approx(1.4 * j0)
    assert "do not pin down" in filled[2]
    assert rigid_fill(v, RigidBody(1.05 * j0, (0.95 * j0, 1.15 * j0), j0, 90.0, 0.9)) is None
    assert rigid_fill(v, RigidBody(1.4 * j0, (0.9 * j0, 2.2 * j0), j0, 15.0, 0.6)) is None
    assert rigid_fill(v, RigidBody(None, None, j0, 3.0, None, "too short")) is None
