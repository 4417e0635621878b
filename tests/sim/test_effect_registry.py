"""The effect library is found module by module: a new effect is one file (plus its test)."""

from __future__ import annotations

import sys
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest

from sim import load_vehicle
from sim.effects import EFFECTS, discover, get_effect
from sim.effects.base import Effect

NEW_EFFECT = '''
"""``mesh_wear``: a test-only effect, written as a new library module would be."""

from typing import Any

from sim.effects.base import Effect, ParamSpec, Values


def _changes(vehicle: Any, v: Values) -> dict[str, Any]:
    return {"gaps.mesh1": v["scale"] * vehicle.get("gaps.mesh1")}


EFFECT = Effect(
    id="mesh_wear",
    title="Worn first gear mesh",
    params=(ParamSpec("scale", "-", 1.0, 3.0, 1.0, "first-mesh clearance as a multiple of the file's"),),
    vehicle_change=_changes,
    order=5,
)
'''


def _package(tmp_path: Path, name: str, modules: dict[str, str]) -> list[str]:
    pkg = tmp_path / name
    pkg.mkdir()
    (pkg / "__init__.py").write_text("", encoding="utf-8")
    for mod, text in modules.items():
        (pkg / f"{mod}.py").write_text(textwrap.dedent(text), encoding="utf-8")
    return [str(pkg)]


@pytest.fixture
def importable(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[Path]:
    monkeypatch.syspath_prepend(str(tmp_path))
    yield tmp_path
    for mod in [m for m in sys.modules if m.startswith("fx_effects")]:
        del sys.modules[mod]


def test_the_library_keeps_its_order() -> None:
    """The candidates' order (reports, fits) is each module's ``order``, the order the library always had."""
    assert list(EFFECTS)[:7] == ["backlash", "housing_mount", "torque_lag", "speed_sensor", "drag",
                                 "progressive_stiffness", "tyre_slip"]
    assert [e.order for e in EFFECTS.values()] == sorted(e.order for e in EFFECTS.values())
    assert all(eid == e.id for eid, e in EFFECTS.items())


def test_a_new_module_is_a_new_effect(importable: Path) -> None:
    """One file, nothing else edited: found, placed by its order, and it changes a vehicle as declared."""
    path = _package(importable, "fx_effects_a", {"mesh_wear": NEW_EFFECT})
    found = discover("fx_effects_a", path)
    assert list(found) == ["mesh_wear"]
    eff = found["mesh_wear"]
    assert isinstance(eff, Effect) and eff.names == ("scale",)
    v = load_vehicle("paper")
    assert eff.apply(v, {"scale": 2.0}).get("gaps.mesh1") == pytest.approx(2.0 * v.get("gaps.mesh1"))
    assert eff.apply(v, eff.off_values()).to_dict() == v.to_dict()
    # the sort key: a module of order 5 sorts before the library's first (10), whatever its name
    both = {**found, **EFFECTS}
    assert sorted(both.values(), key=lambda e: (e.order, e.id))[0].id == "mesh_wear"


@pytest.mark.parametrize(("text", "why"), [
    ("X = 1\n", "no EFFECT"),
    (NEW_EFFECT.replace('id="mesh_wear"', 'id="wear"'), "id differs from the module name"),
])
def test_a_module_without_a_proper_effect_names_its_file(importable: Path, text: str, why: str) -> None:
    path = _package(importable, f"fx_effects_{len(why)}", {"mesh_wear": text})
    with pytest.raises(TypeError, match=r"fx_effects_\d+/mesh_wear\.py must define EFFECT"):
        discover(f"fx_effects_{len(why)}", path)


def test_the_base_module_and_private_modules_are_not_effects(importable: Path) -> None:
    path = _package(importable, "fx_effects_b", {"base": "X = 1\n", "_helpers": "Y = 2\n", "mesh_wear": NEW_EFFECT})
    assert list(discover("fx_effects_b", path)) == ["mesh_wear"]
    with pytest.raises(Exception, match="known: backlash"):
        get_effect("mesh_wear")  # a test package never joins the product's library
