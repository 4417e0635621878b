"""Read endpoints the dashboard needs and scripts can use too: the candidate effects of a
diagnosis, and two versions of a vehicle compared field by field."""

from __future__ import annotations

import hashlib
import math
import tomllib
from pathlib import Path
from typing import Annotated, Any

from fastapi import APIRouter, Query

from app.api.deps import StoreDep
from app.api.schemas import ERRORS, EffectOut, FieldChange, VehicleCompareOut
from app.errors import InputError
from sim.effects import EFFECTS

router = APIRouter(responses=ERRORS)


@router.get("/effects", response_model=list[EffectOut], tags=["diagnoses"],
            summary="Candidate effects a diagnosis can fit (ids for the 'candidates' option)")
def list_effects() -> list[EffectOut]:
    return [EffectOut(id=e.id, title=e.title, model=e.model, params=[p.name for p in e.params])
            for e in EFFECTS.values()]


def flatten(doc: Any, prefix: str = "") -> dict[str, Any]:
    """Nested TOML tables as dotted keys; arrays of tables (``[[stage]]``) indexed: ``stage.0.kind``."""
    out: dict[str, Any] = {}
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.update(flatten(v, f"{prefix}{k}."))
    elif isinstance(doc, list) and any(isinstance(v, dict) for v in doc):
        for i, v in enumerate(doc):
            out.update(flatten(v, f"{prefix}{i}."))
    else:
        out[prefix[:-1]] = doc
    return out


def _change(field: str, a: Any, b: Any) -> FieldChange:
    delta = ratio = None
    numeric = all(isinstance(x, int | float) and not isinstance(x, bool) for x in (a, b))
    if numeric:
        delta = float(b) - float(a)
        ratio = float(b) / float(a) if a and math.isfinite(float(a)) else None
    return FieldChange(field=field, a=a, b=b, changed=a != b, delta=delta, ratio=ratio)


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@router.get("/vehicles/{name}/compare", response_model=VehicleCompareOut, tags=["vehicles"],
            summary="Two versions of a vehicle compared field by field (driveline) and file by file")
def compare_versions(name: str, store: StoreDep, a: Annotated[int, Query(ge=1, description="first version")],
                     b: Annotated[int, Query(ge=1, description="second version")]) -> VehicleCompareOut:
    """Every driveline field of either version (dotted TOML keys), with ``delta = b - a`` and
    ``ratio = b / a`` for numbers; ``files_changed`` names the DBC or signal map when they differ."""
    va, vb = store.get_vehicle(name, a), store.get_vehicle(name, b)
    try:
        fa = flatten(tomllib.loads(va.driveline_path.read_text(encoding="utf-8")))
        fb = flatten(tomllib.loads(vb.driveline_path.read_text(encoding="utf-8")))
    except tomllib.TOMLDecodeError as exc:  # stored files were checked at upload; this is damage on disk
        raise InputError(f"stored driveline of {name} is not readable TOML: {exc}", code="invalid_parameter") from exc
    fields = [_change(k, fa.get(k), fb.get(k)) for k in sorted(fa.keys() | fb.keys())]
    files = [label for label, pa, pb in (("database", va.database_path, vb.database_path),
                                         ("signal_map", va.signal_map_path, vb.signal_map_path))
             if _digest(pa) != _digest(pb)]
    return VehicleCompareOut(name=name, a=a, b=b, fields=fields, files_changed=files,
                             changed=sum(1 for f in fields if f.changed))
