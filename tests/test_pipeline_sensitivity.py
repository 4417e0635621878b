"""Gap sensitivity of a vehicle: the unit is stated, per-mm and per-rad values agree with the geometry."""

from __future__ import annotations

from typing import Any

import pytest

from app.cli.analyze import gap_sensitivity_table
from app.pipeline import gap_sensitivity
from sim import GAP_NAMES, load_vehicle

PAPER = load_vehicle("paper")


@pytest.fixture(scope="module")
def with_radii() -> dict[str, Any]:
    return gap_sensitivity(PAPER)


@pytest.fixture(scope="module")
def without_a_radius() -> dict[str, Any]:
    return gap_sensitivity(PAPER.with_changes({"gaps.spline.radius_mm": 0.0}))


def test_per_mm_when_every_gap_has_a_contact_radius(with_radii: dict[str, Any]) -> None:
    assert with_radii["sensitivity_unit"] == "mm" and "per mm" in with_radii["sensitivity_definition"]
    rows = with_radii["gaps"]
    assert [g["gap"] for g in rows] == list(GAP_NAMES)
    r_half = PAPER.gaps.halfshaft.radius_mm
    for g in rows:
        gap = getattr(PAPER.gaps, g["gap"])
        assert g["radius_mm"] == gap.radius_mm
        assert g["clearance_mm"] == pytest.approx(gap.nominal * gap.radius_mm)
        assert g["sensitivity"] == g["sensitivity_per_mm"]
        # both are normalised to the half-shaft, so they differ by the ratio of contact radii
        assert g["sensitivity_per_mm"] == pytest.approx(g["sensitivity_per_rad"] * r_half / gap.radius_mm, rel=1e-9)
    assert rows[-1]["sensitivity_per_mm"] == pytest.approx(100.0)
    assert rows[-1]["sensitivity_per_rad"] == pytest.approx(100.0)
    # the ranking changes with the unit: the spline's radius is smaller than the half-shaft's
    assert rows[0]["sensitivity_per_mm"] > rows[0]["sensitivity_per_rad"]


def test_per_rad_when_a_radius_is_missing(without_a_radius: dict[str, Any], with_radii: dict[str, Any]) -> None:
    assert without_a_radius["sensitivity_unit"] == "rad"
    spline = without_a_radius["gaps"][0]
    assert spline["radius_mm"] is None and spline["clearance_mm"] is None
    for g, ref in zip(without_a_radius["gaps"], with_radii["gaps"], strict=True):
        assert g["sensitivity_per_mm"] is None
        assert g["sensitivity"] == g["sensitivity_per_rad"] == pytest.approx(ref["sensitivity_per_rad"], rel=1e-9)


def test_table_names_the_unit(with_radii: dict[str, Any], without_a_radius: dict[str, Any]) -> None:
    mm = gap_sensitivity_table(with_radii)
    assert "per mm of gap (circumferential clearance)" in mm.splitlines()[0]
    assert "S per mm" in mm and "S per rad" in mm and "halfshaft" in mm
    rad = gap_sensitivity_table(without_a_radius)
    assert "per rad of gap" in rad.splitlines()[0] and "radius_mm" in rad.splitlines()[-1]


def test_every_case_reports_what_the_driver_feels(with_radii: dict[str, Any]) -> None:
    nominal, zero = with_radii["nominal"], with_radii["zero_gaps"]
    half = next(g for g in with_radii["gaps"] if g["gap"] == "halfshaft")["halved"]
    for case in (nominal, zero, half):
        assert {"shuffle_pp_ms2", "kick_ms2", "max_jerk_ms3", "vdv_ms175"} <= set(case)
    # less lash, less shuffle felt in the body: halving the half-shaft's lash, removing all of it
    assert half["shuffle_pp_ms2"] < 0.8 * nominal["shuffle_pp_ms2"]
    assert zero["shuffle_pp_ms2"] < 0.8 * nominal["shuffle_pp_ms2"]
    assert "felt (body acceleration): shuffle peak-to-peak nominal" in gap_sensitivity_table(with_radii)


def test_simulate_what_if_prints_the_felt_change(tmp_path: Any, capsys: pytest.CaptureFixture[str]) -> None:
    import numpy as np

    from app.cli import main

    t = np.arange(0.0, 2.0, 0.01)
    q = np.where(t < 0.5, -50.0, np.minimum(150.0, -50.0 + (t - 0.5) * 1500.0))
    csv = tmp_path / "tip_in.csv"
    csv.write_text("t_s,torque_nm\n" + "".join(f"{a},{b}\n" for a, b in zip(t, q, strict=True)), encoding="utf-8")
    assert main(["simulate", str(csv), "--vehicle", "paper", "--what-if", "gap=halfshaft:0.5"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("felt"))
    before, after = (float(v) for v in line.split("shuffle peak-to-peak ")[1].split(" m/s^2")[0].split(" -> "))
    assert after < 0.7 * before
