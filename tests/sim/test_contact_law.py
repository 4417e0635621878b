"""The contact law's two ways of engaging a damper (``Vehicle.contact_damping``): definition, file, kernels."""

from __future__ import annotations

import numpy as np
import pytest

from sim import ParameterError, Vehicle, load_vehicle, simulate
from sim.batch import simulate_batch
from sim.integrate import contact_torque
from sim.metrics import peak_to_valley
from sim.model import CONTACT_RAMP, build_chain
from sim.paper import tip_in_torque
from sim.reference import coupling_matrix, solve_reference
from sim.simulate import RPM
from sim.vehicle_file import dump_toml
from tests.conftest import REPO

PAPER = load_vehicle("paper")
FULL = PAPER.with_changes({"contact_damping": "full"})
torque = contact_torque.py_func  # the compiled law's own Python, for exact values


def test_the_default_law_is_limited_and_a_file_without_the_key_reads_as_before() -> None:
    assert PAPER.contact_damping == "limited"
    assert "contact_damping" not in PAPER.to_dict()
    assert not np.any(PAPER.compiled.cramp)
    assert PAPER.with_changes({"contact_damping": "limited"}) == PAPER
    assert FULL.to_dict()["contact_damping"] == "full"
    assert Vehicle.from_dict(FULL.to_dict()) == FULL


def test_the_law_is_written_to_and_read_from_a_vehicle_file(tmp_path) -> None:  # type: ignore[no-untyped-def]
    path = tmp_path / "full.toml"
    path.write_text(dump_toml(FULL), encoding="utf-8")
    assert 'contact_damping = "full"' in path.read_text(encoding="utf-8")
    back = load_vehicle(str(path))
    assert back.contact_damping == "full"
    m = back.compiled
    assert np.array_equal(m.cramp, CONTACT_RAMP * m.chalf)  # every gap's damper engages over its own ramp


def test_an_unknown_law_is_a_parameter_error() -> None:
    with pytest.raises(ParameterError, match=r"contact_damping = 'soft'.*'limited', 'full'"):
        PAPER.with_changes({"contact_damping": "soft"})
    data = PAPER.to_dict() | {"contact_damping": 3}
    with pytest.raises(ParameterError, match="contact_damping"):
        Vehicle.from_dict(data)


def test_the_two_laws_in_numbers() -> None:
    k, c, half, ramp = 1000.0, 10.0, 0.01, 0.001
    # 1 mrad into contact, closing at 1 rad/s: spring 1 N m, damper 10 N m
    assert torque(0.011, 1.0, k, 0.0, c, half, 0.0) == pytest.approx(2.0)  # limited: the damper to the spring's 1
    assert torque(0.011, 1.0, k, 0.0, c, half, ramp) == pytest.approx(11.0)  # full: the damper in full
    assert torque(0.0105, 1.0, k, 0.0, c, half, ramp) == pytest.approx(0.5 + 5.0)  # half the ramp: half the damper
    assert torque(-0.011, -1.0, k, 0.0, c, half, ramp) == pytest.approx(-11.0)  # the other flank, mirrored
    assert torque(-0.0105, -1.0, k, 0.0, c, half, ramp) == pytest.approx(-5.5)
    # opening fast: a contact never pulls, under either law
    for r in (0.0, ramp):
        assert torque(0.011, -10.0, k, 0.0, c, half, r) == 0.0
        assert torque(-0.011, 10.0, k, 0.0, c, half, r) == 0.0
        assert torque(0.005, 1.0, k, 0.0, c, half, r) == 0.0  # inside the clearance
    # the cubic term counts as spring
    assert torque(0.011, 0.0, k, 1e9, c, half, ramp) == pytest.approx(1.0 + 1.0)
    # no clearance: a plain spring-damper, whatever the ramp says
    assert torque(0.002, 1.0, k, 0.0, c, 0.0, ramp) == torque(0.002, 1.0, k, 0.0, c, 0.0, 0.0) == pytest.approx(12.0)


def test_full_law_against_tight_solve_ivp_reference() -> None:
    """The kernel's full law and the reference's (its own vectorised code) agree as the limited law does (within
    1 rpm peak-to-valley of the shuffle)."""
    t, q = tip_in_torque(1.0, duration_s=0.45)
    res = simulate(FULL, t, q, interp="linear")
    m = build_chain(FULL)
    fine = np.arange(0.0, 0.45, 2e-5)
    _, omega, _ = solve_reference(m, t, q, True, res.rotor_speed_rpm[0] / RPM, fine, rtol=1e-8, atol=1e-9)
    ref = np.interp(res.t, fine, (omega[:, m.rotor] - omega[:, m.housing]) * RPM)
    ours = peak_to_valley(res.t, res.motor_speed_rpm, 0.0, 0.45)
    assert ours > 100.0
    assert ours == pytest.approx(peak_to_valley(res.t, ref, 0.0, 0.45), abs=1.0)
    assert coupling_matrix(m).shape == (m.n_couplings, m.n_bodies)


def test_without_lash_the_laws_are_the_same_model() -> None:
    t, q = tip_in_torque(duration_s=0.3)
    tight = PAPER.with_changes({f"gaps.{g}": 0.0 for g in ("spline", "mesh1", "mesh2", "differential", "halfshaft")})
    a = simulate(tight, t, q).motor_speed_rpm
    b = simulate(tight.with_changes({"contact_damping": "full"}), t, q).motor_speed_rpm
    assert np.array_equal(a, b)


def test_the_law_matters_on_a_soft_damped_shaft_and_hardly_on_the_paper_car() -> None:
    """The limited damper hardly damps a soft, heavily damped shaft at impact: after a tip-out through the lash the
    motor speed swings further than with the damper in full. On the paper's stiff, lightly damped driveline the
    two laws differ by well under 1 %."""
    chain = load_vehicle(str(REPO / "bench" / "indep" / "chain_low.toml"))
    soft = chain.with_changes({f"stage.{n}.damping": 3.0 * float(chain.get(f"stage.{n}.damping"))
                               for n in ("motor_shaft", "chain", "differential", "halfshaft")})
    t = np.arange(0.0, 1.5, 0.01)
    q = np.interp(t, [0.0, 0.5, 0.55, 1.5], [60.0, 60.0, -30.0, -30.0])
    swing = {law: peak_to_valley(r.t, r.motor_speed_rpm, 0.5, 1.5) for law in ("limited", "full")
             for r in [simulate(soft.with_changes({"contact_damping": law}), t, q, interp="linear")]}
    assert swing["full"] < 0.95 * swing["limited"]
    tp, qp = tip_in_torque(duration_s=0.45)
    paper = {v.contact_damping: peak_to_valley(r.t, r.motor_speed_rpm, 0.0, 0.45)
             for v in (PAPER, FULL) for r in [simulate(v, tp, qp, interp="linear")]}
    assert paper["full"] == pytest.approx(paper["limited"], rel=0.01)
    assert paper["full"] != paper["limited"]


def test_batch_variants_may_differ_in_law() -> None:
    t, q = tip_in_torque(duration_s=0.4)
    variants = [{}, {"contact_damping": "full"}, {"contact_damping": "full", "body.mass": 1900.0}]
    batch = simulate_batch(PAPER, variants, t, q, interp="linear")
    for k, change in enumerate(variants):
        single = simulate(PAPER.with_changes(change), t, q, interp="linear")
        assert np.allclose(batch.motor_speed_rpm[k], single.motor_speed_rpm, atol=1e-9)
        assert batch.gap_events[k] == single.gap_events


def test_the_two_inertia_model_has_no_contact_law() -> None:
    """Its one lumped lash follows the paper's equations: the law leaves it unchanged, bit for bit."""
    t, q = tip_in_torque(duration_s=0.3)
    a = simulate(PAPER, t, q, model="two_inertia").motor_speed_rpm
    assert np.array_equal(a, simulate(FULL, t, q, model="two_inertia").motor_speed_rpm)
