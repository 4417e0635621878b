"""Read endpoints the dashboard needs and scripts can use too: the candidate effects of a
diagnosis, and two versions of a vehicle compared field by field."""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Annotated

from fastapi import APIRouter, Query

from app.api.deps import StoreDep
from app.api.schemas import ERRORS, EffectOut, FieldChange, FigureChange, VehicleCompareOut
from app.errors import InputError
from app.vehicle_compare import compare_texts
from sim.effects import EFFECTS

router = APIRouter(responses=ERRORS)


@router.get("/effects", response_model=list[EffectOut], tags=["diagnoses"],
            summary="Candidate effects a diagnosis can fit (ids for the 'candidates' option)")
def list_effects() -> list[EffectOut]:
    return [EffectOut(id=e.id, title=e.title, model=e.model, params=[p.name for p in e.params])
            for e in EFFECTS.values()]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


@router.get("/vehicles/{name}/compare", response_model=VehicleCompareOut, tags=["vehicles"],
            summary="Two versions of a vehicle compared field by field (driveline) and file by file")
def compare_versions(name: str, store: StoreDep, a: Annotated[int, Query(ge=1, description="first version")],
                     b: Annotated[int, Query(ge=1, description="second version")]) -> VehicleCompareOut:
    """The figures the base parameters are reported as (torsional stiffness at the motor, first mode and its damping
    ratio, mass, total lash, torque gain) of both, with ``ratio = b / a``; every driveline field of either version
    (dotted TOML keys), with ``delta = b - a`` and ``ratio = b / a`` for numbers; each version's ``[provenance]``
    when it was identified; ``files_changed`` names the DBC or signal map when they differ."""
    va, vb = store.get_vehicle(name, a), store.get_vehicle(name, b)
    try:  # stored files were checked at upload; a failure here is damage on disk
        cmp = compare_texts(va.driveline_path.read_text(encoding="utf-8"),
                            vb.driveline_path.read_text(encoding="utf-8"), f"{name} version {a}", f"{name} version {b}")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"stored driveline of {name} cannot be read: {exc}", code="invalid_parameter") from exc
    files = [label for label, pa, pb in (("database", va.database_path, vb.database_path),
                                         ("signal_map", va.signal_map_path, vb.signal_map_path))
             if _digest(pa) != _digest(pb)]
    return VehicleCompareOut(name=name, a=a, b=b, fields=[FieldChange(**f) for f in cmp.fields], files_changed=files,
                             changed=len(cmp.changed), figures=[FigureChange(**f) for f in cmp.figures],
                             provenance=cmp.provenance)
