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
