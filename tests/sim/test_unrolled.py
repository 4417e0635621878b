"""The speed-only loop written out per chain layout (:mod:`sim.unrolled`) gives the generic kernel's numbers.

Every serial layout a fit meets runs the generated kernel when neither states nor gap events are kept; its
resolver, sensor and torque rows must be those of the tracked loop of :func:`sim.integrate.run_chain` bit for bit,
with and without housing, tyre body, cubic springs, brake, hub and rotor drag, input lag and speed filter.
"""

from __future__ import annotations

import math
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import sim.runner as runner
from sim import load_vehicle
from sim.effects import apply_effects
from sim.errors import InstabilityError
from sim.integrate import GRAVITY, road_load_torque
from sim.model import quasi_static_full
from sim.params import Vehicle
from sim.runner import is_serial, run_from_state
from sim.simulate import choose_step
from sim.unrolled import _folder, _module, _source, needs_cubic, serial_kernel
from tests.sim.test_topologies import unequal_chain_drive

TYRE = {"tyre_slip": {"compliance_per_mn": 40.0, "relaxation_m": 0.3}}
CASES: dict[str, Callable[[], Vehicle]] = {
    "paper": lambda: load_vehicle("paper"),
    "paper_fitted": lambda: load_vehicle("paper_fitted"),
    "chain_drive": lambda: load_vehicle("chain_drive"),
    "chain_full": lambda: load_vehicle("chain_drive").with_changes({"contact_damping": "full"}),
    "single_reduction": lambda: load_vehicle("single_reduction"),
    "no_housing": lambda: load_vehicle("paper").with_changes({"housing.enabled": False}),
    "no_housing_tyre": lambda: apply_effects(load_vehicle("paper").with_changes({"housing.enabled": False}), TYRE),
    "brake_hub_rotor_drag": lambda: load_vehicle("paper").with_changes(
        {"body.brake_torque": 40.0, "wheel.viscous_drag": 0.3, "wheel.coulomb_drag": 2.0, "motor.coulomb_drag": 0.4}),
    "all_effects": lambda: apply_effects(load_vehicle("paper"), {
        "drag": {"coulomb_nm": 4.0, "viscous_nms": 0.01},
        "progressive_stiffness": {"halfshaft_rel": 0.5, "mount_rel": 0.5},
        "torque_lag": {"delay_s": 0.004, "tau_s": 0.003},
        "speed_sensor": {"tau_s": 0.002, "delay_s": 0.003}, **TYRE}),
}


def _runs(v: Vehicle, q_scale: float = 1.0) -> tuple[Any, Any]:
    m = v.compiled
    t = np.arange(0.0, 3.0, 0.01)
    q = q_scale * (np.where(t < 1.0, -30.0, 90.0) + 5.0 * np.sin(7.0 * t))
    theta0, omega0, tyre0 = quasi_static_full(m, float(q[0]), 150.0)
    step, sub = choose_step(m, 1e-3, torque_max=float(np.max(np.abs(q))))
    eff = v.effects
    kw: dict[str, Any] = {"lag": (eff.torque_lag.delay_s, eff.torque_lag.tau_s), "sensor_tau": eff.speed_sensor.tau_s,
                          "speed_limit": 20.0 * 150.0 + 5000.0}
    full = run_from_state(m, t, q, True, 0.0, step, sub, 2901, theta0, omega0, tyre0, **kw)
    lean = run_from_state(m, t, q, True, 0.0, step, sub, 2901, theta0, omega0, tyre0, events=False, states=False,
                          **kw)
    return full, lean


@pytest.fixture
def kernel_calls(monkeypatch: pytest.MonkeyPatch) -> list[tuple[Any, ...]]:
    """The layouts the generated kernels were asked for."""
    calls: list[tuple[Any, ...]] = []

    def spy(*key: Any) -> Any:
        calls.append(key)
        return serial_kernel(*key)

    monkeypatch.setattr(runner, "serial_kernel", spy)
    return calls


@pytest.mark.parametrize("which", sorted(CASES))
def test_the_written_out_loop_gives_the_tracked_loop_s_rows_bit_for_bit(
        which: str, kernel_calls: list[tuple[Any, ...]]) -> None:
    v = CASES[which]()
    m = v.compiled
    assert is_serial(m)
    full, lean = _runs(v)
    assert kernel_calls, "the serial layout did not take the generated kernel"
    nch = m.n_couplings - (1 if m.housing >= 0 else 0)
    assert kernel_calls[-1] == (m.n_bodies, nch, m.rotor, m.wheel, m.housing, m.vehicle, bool(np.any(m.ck3 != 0.0)))
    assert full.events  # the gaps open and close: the contact law's every branch is taken
    for name in ("resolver", "sensor", "torque"):
        assert np.array_equal(getattr(lean, name), getattr(full, name)), name
    assert np.ptp(lean.resolver) > 1.0  # a drive that moves
    assert lean.omega.shape[0] == 0 and lean.events == []


def test_a_layout_that_is_not_serial_keeps_the_generic_kernel(kernel_calls: list[tuple[Any, ...]]) -> None:
    v = unequal_chain_drive()
    assert not is_serial(v.compiled)
    full, lean = _runs(v)
    assert kernel_calls == []
    assert np.array_equal(lean.resolver, full.resolver)


def test_a_diverging_run_is_refused_as_by_the_generic_kernel() -> None:
    v = load_vehicle("paper").with_changes({"motor.rotor_inertia": 1e-4})
    with pytest.raises(InstabilityError) as tracked:
        _runs(v, q_scale=1e6)
    m = v.compiled
    t = np.arange(0.0, 3.0, 0.01)
    q = 1e6 * (np.where(t < 1.0, -30.0, 90.0) + 5.0 * np.sin(7.0 * t))
    theta0, omega0, tyre0 = quasi_static_full(m, float(q[0]), 150.0)
    step, sub = choose_step(m, 1e-3, torque_max=float(np.max(np.abs(q))))
    with pytest.raises(InstabilityError) as lean:
        run_from_state(m, t, q, True, 0.0, step, sub, 2901, theta0, omega0, tyre0, events=False, states=False,
                       speed_limit=20.0 * 150.0 + 5000.0)
    assert str(lean.value) == str(tracked.value) and "diverging speed" in str(lean.value)


def test_the_cubic_term_is_left_out_only_where_it_adds_nothing() -> None:
    m = load_vehicle("paper").compiled
    assert not needs_cubic(m.ck, m.ck3)
    prog = apply_effects(load_vehicle("paper"), {"progressive_stiffness": {"halfshaft_rel": 0.5, "mount_rel": 0.5}})
    assert needs_cubic(prog.compiled.ck, prog.compiled.ck3)
    assert needs_cubic(m.ck, np.where(np.arange(m.ck3.size) == 2, -0.0, m.ck3))  # a negative zero keeps it
    assert needs_cubic(np.where(np.arange(m.ck.size) == 1, -1.0, m.ck), m.ck3)
    assert "contact_torque_linear(" in _source(8, 6, 0, 6, 7, -1, False)
    assert "contact_torque_linear(" not in _source(8, 6, 0, 6, 7, -1, True)


def test_the_source_is_written_once_per_layout_where_asked(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("LASHSCOPE_KERNEL_DIR", str(tmp_path / "kernels"))
    key = (5, 4, 0, 4, -1, -1, False)
    mod = _module(key)
    files = list((tmp_path / "kernels").glob("lashscope_serial_*.py"))
    assert len(files) == 1 and files[0].read_text() == _source(*key)
    stamp = files[0].stat().st_mtime_ns
    _module(key)  # unchanged: not rewritten, so numba's cache of it stays valid
    assert files[0].stat().st_mtime_ns == stamp
    assert callable(mod.run)
    assert serial_kernel(8, 6, 0, 6, 7, -1, False) is serial_kernel(8, 6, 0, 6, 7, -1, False)


def test_a_folder_others_can_write_to_is_not_used(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Its files are imported: a kernel folder writable by other users is passed over for a private one."""
    shared = tmp_path / "shared"
    shared.mkdir()
    shared.chmod(0o777)
    monkeypatch.setenv("LASHSCOPE_KERNEL_DIR", str(shared))
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    chosen = _folder()
    assert chosen != shared and chosen == tmp_path / "home" / ".cache" / "lashscope" / "kernels"
    assert not chosen.stat().st_mode & 0o077
    shared.chmod(0o755)
    assert _folder() == shared


def test_another_integrate_module_makes_another_file(monkeypatch: pytest.MonkeyPatch) -> None:
    """numba's cache checks only the generated file's own time stamp: the functions it inlines from
    sim/integrate.py must name their version in the source, so that a changed contact law is compiled afresh."""
    import sim.unrolled as unrolled

    key = (8, 6, 0, 6, 7, -1, False)
    before = _source(*key)
    assert unrolled._integrate_hash() in before
    monkeypatch.setattr(unrolled, "_integrate_hash", lambda: "0123456789abcdef")
    assert _source(*key) != before


def test_no_writable_folder_runs_the_generic_loop(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                  caplog: pytest.LogCaptureFixture) -> None:
    """A read-only file system: the generic loop, the same numbers, and one line in the log saying why."""
    import sim.unrolled as unrolled

    def refuse() -> Path:
        raise OSError("no private writable folder for the generated kernels")

    monkeypatch.setattr(unrolled, "_folder", refuse)
    monkeypatch.setattr(unrolled, "_KERNELS", {})
    v = load_vehicle("single_reduction")
    with caplog.at_level("WARNING", logger="sim.unrolled"):
        full, lean = _runs(v)
        _runs(v)  # asked again: not tried again, not said again
    assert np.array_equal(lean.resolver, full.resolver) and np.ptp(lean.resolver) > 1.0
    said = [r for r in caplog.records if "generic loop" in r.getMessage()]
    assert len(said) == 1 and "no private writable folder" in said[0].getMessage()


def test_numba_s_cache_folder_is_used_where_it_is_set(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A container sets NUMBA_CACHE_DIR (the image's user has the data volume as its home): the generated sources
    go beside numba's cache, not into the user's home."""
    monkeypatch.delenv("LASHSCOPE_KERNEL_DIR", raising=False)
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert _folder() == tmp_path / "numba" / "lashscope-kernels"
    assert not (tmp_path / "home").exists()


def test_the_road_load_skips_its_division_only_where_the_sign_is_exact() -> None:
    """``road_load_torque`` takes the rolling resistance's sign as +-1 beyond 2.0000001 m/s without dividing by 0.1:
    the same numbers as ``tanh(v / 0.1)`` clamped at |x| > 20, on both sides of the boundary and at standstill."""
    road = load_vehicle("paper").compiled.road
    radius = float(road[0])
    v = np.concatenate([np.linspace(-40.0, 40.0, 4001), np.array([0.0, -0.0, 1e-300, 2.0, -2.0]),
                        np.nextafter(2.0, np.array([0.0, 4.0])), np.nextafter(2.0000001, np.array([0.0, 4.0])),
                        -np.nextafter(2.0000001, np.array([0.0, 4.0])), np.linspace(1.999, 2.001, 2001)])
    for speed in v:
        omega = speed / radius
        vv = omega * road[0]
        x = vv / 0.1
        sgn = 1.0 if x > 20.0 else (-1.0 if x < -20.0 else math.tanh(x))
        force = road[2] * road[1] * GRAVITY * sgn + road[3] * vv * abs(vv) + road[1] * GRAVITY * road[4]
        assert road_load_torque(road, omega) == road[0] * force, speed
