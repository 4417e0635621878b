"""The stage-kind registry (sim/stagekinds): one module per kind, the docs' table from it, typed lookups."""

from __future__ import annotations

import pkgutil
from pathlib import Path

import pytest

import sim.stagekinds as stagekinds
from sim import ParameterError, Vehicle, load_vehicle
from sim.stagekinds import ALIASES, DIFFERENTIAL, DRIVE, KINDS, SHAFTS, kind_of, kinds_table
from tests.sim.test_stages import preset_data

DOC = Path(__file__).resolve().parents[2] / "docs" / "simulation.md"


def test_every_module_is_a_registered_kind() -> None:
    modules = {m.name for m in pkgutil.iter_modules(stagekinds.__path__)} - {"base"}
    assert set(KINDS) == modules
    assert {"spline", "gear", "planetary", "chain", "differential", "halfshaft", "flexible_coupling"} <= set(KINDS)
    assert ALIASES == {"coupling": "spline", "belt": "chain"}
    assert [k.role for k in KINDS.values()].count(DIFFERENTIAL) == 1
    assert [k.role for k in KINDS.values()].count(SHAFTS) == 1
    assert all(k.role in (DRIVE, DIFFERENTIAL, SHAFTS) for k in KINDS.values())


def test_the_docs_table_is_the_registry() -> None:
    """docs/simulation.md lists exactly the registered kinds, each with its own row, in registry order."""
    text = DOC.read_text(encoding="utf-8")
    table = kinds_table()
    assert table in text, "regenerate the stage table: print(sim.stagekinds.kinds_table())"
    rows = [line for line in text.splitlines() if line.startswith("| `") and "housing" not in line.split("|")[1]]
    kind_rows = [r for r in rows if r.split("|")[1].strip().split()[0].strip("`") in KINDS]
    assert kind_rows == [k.doc_row() for k in KINDS.values()]


def test_unknown_kind_is_a_typed_error_naming_the_known_ones() -> None:
    with pytest.raises(ParameterError) as exc:
        kind_of("sprocket", "stage 2 'chain': kind")
    text = str(exc.value)
    assert text.startswith("stage 2 'chain': kind = 'sprocket': unknown stage kind; known: ['spline'")
    assert all(f"'{k}'" in text for k in KINDS)
    with pytest.raises(ParameterError):
        kind_of(["gear"])  # type: ignore[arg-type]  # not hashable: still the typed error
    assert kind_of("belt") is KINDS["chain"]


def test_unhashable_kind_in_a_file_is_named() -> None:
    data = preset_data("chain_drive")
    data["stage"][2]["kind"] = ["chain"]
    with pytest.raises(ParameterError, match=r"stage 2 'chain': kind = \['chain'\]: unknown stage kind"):
        Vehicle.from_dict(data)


def test_reference_stages_exist_in_the_paper_preset() -> None:
    """The vehicle check compares each stage with the paper's stage its kind names: that stage must exist."""
    paper = {s.name for s in load_vehicle("paper").chain}
    assert {k.reference_stage for k in KINDS.values()} <= paper


def test_vehicle_check_compares_every_kind_with_its_reference_stage() -> None:
    """A stage of any kind with an absurd stiffness is named against the paper stage of its kind."""
    from app.vehicle_check import suspect_fields

    paper = load_vehicle("paper").as_stages()
    for kind in ("gear", "chain", "planetary"):
        data = preset_data("chain_drive")
        data["stage"][2].update(kind=kind, teeth=[11, 42], stiffness=2.0)
        v = Vehicle.from_dict(data)
        assert suspect_fields(v)[0] == ("stage.chain.stiffness", 2.0, paper.stage("mesh2").stiffness)
