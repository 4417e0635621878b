"""Driveline topology: an ordered chain of stages from the rotor to the wheels.

A vehicle file may describe its driveline as ``[[stage]]`` tables in order from the motor to the
wheels (docs/simulation.md, "Stage format"). Each stage joins the body before it (its *input*)
to a new body after it (its *output*) and carries

``stiffness``, ``damping``, ``lash_rad``, ``cubic_stiffness``
    in the **output** shaft's angle (gear pairs: the driven gear; chains: the driven sprocket;
    planetary: the carrier), unless the stage says ``referred_to = "input"``. Lash is the total
    clearance (2 alpha), a number or a table ``{nominal, min, max, radius_mm}`` as ``[gaps.*]``.
``inertia``
    of the output body in its own angle (gear stage: driven gear, its shaft and the next
    pinion; differential: both side gears; half-shaft: one shaft, distributed).

Kinds are the registry :mod:`sim.stagekinds` (one module per kind: its fields, checks, kernel
wiring and docs line); this module reads and checks the tables and the chain's order by their
kind's role (drive stages, then at most one differential, then at most one half-shaft stage).
The file may also put the rotor and the wheels in the chain as its first (``kind = "rotor"``,
the ``[motor]`` fields) and last (``kind = "wheel"``, the ``[wheel]`` fields) entries.
Validation names the stage by index and name: ``stage 2 'chain': lash_rad``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from sim.errors import ParameterError
from sim.fields import INT_POS, NONNEG, POS, check
from sim.fields import num as _f
from sim.optional import CUBIC_STIFFNESS as CUBIC
from sim.params_base import DAMPING, INERTIA, LASH_RAD, SEGMENTS, STIFFNESS, Gap, gap_from_mm
from sim.stagekinds import DIFFERENTIAL, DRIVE, SHAFTS, StageKind, kind_names, kind_of
from sim.stagekinds.base import STAGE_RATIO

MAX_STAGES = 24  # decided before any stage is parsed: what one check, analysis or what-if may cost
END_TABLES = {"rotor": "motor", "wheel": "wheel"}  # end entries of the chain -> their own tables
RESERVED = frozenset({"rotor", "wheel", "wheels", "housing", "vehicle", "mount", "tyre"})  # the model's own bodies


@dataclass(frozen=True, kw_only=True)
class Shaft:
    """The right half-shaft's own values when the two shafts differ (units as :class:`Stage`)."""

    stiffness: float = _f("N m/rad (shaft angle)", POS, limits=STIFFNESS)
    damping: float = _f("N m s/rad (shaft angle)", NONNEG, limits=DAMPING)
    inertia: float = _f("kg m^2", NONNEG, 0.0, (0.0, INERTIA[1]))
    lash_rad: Gap = dataclasses.field(default_factory=lambda: Gap(nominal=0.0))
    cubic_stiffness: float = _f("N m/rad^3 (shaft angle)", NONNEG, 0.0, CUBIC)


@dataclass(frozen=True, kw_only=True)
class Stage:
    """One stage of the driveline (see the module docstring for the meaning of each field)."""

    kind: str
    name: str
    ratio: float = _f("- (input speed / output speed)", POS, 1.0, STAGE_RATIO)
    stiffness: float = _f("N m/rad (output angle)", POS, 1.0, STIFFNESS)
    damping: float = _f("N m s/rad (output angle)", NONNEG, 0.0, DAMPING)
    inertia: float = _f("kg m^2 (output body, own angle)", NONNEG, 0.0, (0.0, INERTIA[1]))
    lash_rad: Gap = dataclasses.field(default_factory=lambda: Gap(nominal=0.0))
    cubic_stiffness: float = _f("N m/rad^3 (output angle)", NONNEG, 0.0, CUBIC)
    referred_to: str = "output"
    type: str = "open"  # differential only: open | solid
    segments: int = _f("-", INT_POS, 1, SEGMENTS)  # half-shaft only
    count: int = _f("-", INT_POS, 1, (1, 2))  # half-shaft only
    right: Shaft | None = None  # half-shaft only: the right shaft when unequal
    # names of its body and coupling in the model's arrays when not the stage's own (the classic layout's)
    body_name: str = dataclasses.field(default="", compare=False, repr=False)
    coupling_name: str = dataclasses.field(default="", compare=False, repr=False)

    @property
    def spec(self) -> StageKind:
        """The stage's kind from the registry (:mod:`sim.stagekinds`)."""
        return kind_of(self.kind)

    @property
    def has_coupling(self) -> bool:
        """False for a solid axle: the shafts start at the ring gear's body."""
        return self.spec.has_coupling(self)

    @property
    def to_input(self) -> float:
        """Factor from the stage's stated shaft angle to its input shaft angle (lash; k, c use its square)."""
        return self.ratio if self.referred_to == "output" else 1.0

    def gap_names(self) -> tuple[str, ...]:
        if not self.spec.has_gap(self):
            return ()
        return (self.name, f"{self.name}_right") if self.right is not None else (self.name,)


def _label(i: int, name: str) -> str:
    return f"stage {i} '{name}': "


def _build_fields(cls: type, raw: Mapping[str, Any], prefix: str) -> dict[str, Any]:
    """Checked keyword arguments of ``cls`` from ``raw`` (numbers coerced, lash tables built)."""
    out: dict[str, Any] = {}
    metas: dict[str, Mapping[str, Any]] = {f.name: f.metadata for f in dataclasses.fields(cls)}
    for key, value in raw.items():
        path = f"{prefix}{key}"
        if key == "lash_rad":
            out[key] = _gap(value, path)
            continue
        meta: Mapping[str, Any] = metas.get(key, {})
        if "rule" in meta:
            if isinstance(value, int) and not isinstance(value, bool) and meta["rule"] != INT_POS:
                value = float(value)
            check(path, value, meta["rule"], meta.get("limits"), meta.get("unit", ""))
        out[key] = value
    return out


def _gap(value: Any, path: str) -> Gap:
    if isinstance(value, int | float) and not isinstance(value, bool):
        value = {"nominal": value}
    if not isinstance(value, Mapping):
        raise ParameterError(path, value, "must be a number (rad) or a table {nominal, min, max, radius_mm}")
    table = gap_from_mm(value, path + ".")
    known = {"nominal", "min", "max", "radius_mm"}
    for k, v in table.items():
        if k not in known:
            raise ParameterError(f"{path}.{k}", v, f"unknown field; known: {sorted(known)}")
        if isinstance(v, int) and not isinstance(v, bool):
            v = float(v)
        check(f"{path}.{k}" if k != "nominal" else path, v, NONNEG, LASH_RAD if k != "radius_mm" else None, "rad")
    if "nominal" not in table:
        raise ParameterError(f"{path}.nominal", None, "required field missing")
    gap = Gap(**{k: float(v) for k, v in table.items()})
    if not gap.min <= gap.nominal <= gap.max:
        raise ParameterError(path, gap.nominal, f"must lie within its band [min, max] = [{gap.min!r}, {gap.max!r}]")
    return gap


def parse_stage(i: int, raw: Any) -> Stage:
    """One validated :class:`Stage` from its table; errors name ``stage i 'name': field``."""
    if not isinstance(raw, Mapping):
        raise ParameterError(f"stage {i}", raw, "must be a table with a kind")
    name = raw.get("name", raw.get("kind", "?"))
    if not isinstance(name, str) or not name or not name.replace("_", "").isalnum():
        raise ParameterError(f"stage {i} {name!r}: name", name, "must be a word of letters, digits and _")
    label = _label(i, name)
    if name in RESERVED or name.endswith(("_right", "_left")):
        raise ParameterError(f"{label}name", name, f"reserved for the model's own bodies ({sorted(RESERVED)}, "
                             "*_left, *_right)")
    if raw.get("kind") is None:
        raise ParameterError(f"{label}kind", None, f"required field missing; one of {kind_names()}")
    spec = kind_of(raw["kind"], f"{label}kind")
    kind = spec.name
    allowed = set(spec.fields())
    for key in raw:
        if key not in allowed:
            raise ParameterError(f"{label}{key}", raw[key], f"not a field of a {kind} stage; known: {sorted(allowed)}")
    data = {k: v for k, v in raw.items() if k not in ("kind", "name", "teeth", "right")}
    for key in (*spec.required, *spec.extra_required(raw)):
        if key not in raw:
            raise ParameterError(f"{label}{key}", None, f"required field missing for a {kind} stage")
    spec.prepare(raw, data, label)
    if "referred_to" in data and data["referred_to"] not in ("output", "input"):
        raise ParameterError(f"{label}referred_to", data["referred_to"], f"must be one of {['output', 'input']}")
    kw = _build_fields(Stage, data, label)
    if "right" in raw:
        kw["right"] = _shaft(raw["right"], f"{label}right.")
        if kw.get("count", 1) != 2:
            raise ParameterError(f"{label}count", kw.get("count", 1), "a [stage.right] shaft needs count = 2")
    return Stage(kind=kind, name=name, **kw)


def _shaft(raw: Any, prefix: str) -> Shaft:
    if not isinstance(raw, Mapping):
        raise ParameterError(prefix.rstrip("."), raw, "must be a table")
    known = {f.name for f in dataclasses.fields(Shaft)}
    for key in raw:
        if key not in known:
            raise ParameterError(f"{prefix}{key}", raw[key], f"unknown field; known: {sorted(known)}")
    for key in ("stiffness", "damping"):
        if key not in raw:
            raise ParameterError(f"{prefix}{key}", None, "required field missing")
    return Shaft(**_build_fields(Shaft, raw, prefix))


def parse_chain(raw: Any, first: int = 0) -> tuple[Stage, ...]:
    """Validated stages in order; raises ParameterError for a chain that is not rotor -> ... -> wheels.

    ``first`` is the file index of ``raw[0]`` (1 when the file's first entry was the rotor), so
    messages name the stage as the user counts it: ``stage 2 'chain': lash_rad``.
    """
    if not isinstance(raw, list) or not raw:
        raise ParameterError("stage", raw, "must be a non-empty list of [[stage]] tables from rotor to wheels")
    if len(raw) > MAX_STAGES:
        raise ParameterError("stage", f"{len(raw)} stages", f"at most {MAX_STAGES} stages (the limit of a "
                             "driveline; a car has up to about 12): the simulator's cost grows with their square")
    stages = tuple(parse_stage(i + first, s) for i, s in enumerate(raw))
    seen: dict[str, int] = {}
    for i, s in enumerate(stages, start=first):
        if s.name in seen:
            raise ParameterError(f"{_label(i, s.name)}name", s.name, f"already used by stage {seen[s.name]}")
        seen[s.name] = i
    check_topology(stages, first)
    return stages


def check_topology(stages: tuple[Stage, ...], first: int = 0) -> None:
    """Rotor, drive stages, at most one differential, at most one half-shaft stage, in that order.

    Each stage's place follows from its kind's role (:data:`sim.stagekinds.DRIVE`, ``DIFFERENTIAL``,
    ``SHAFTS``)."""
    diff = -1
    for i, s in enumerate(stages):
        label = _label(i + first, s.name)
        role = s.spec.role
        shafts_before = [p for p in stages[:i] if p.spec.role == SHAFTS]
        if role == DRIVE and (diff >= 0 or shafts_before):
            where = stages[diff] if diff >= 0 else shafts_before[0]
            raise ParameterError(f"{label}kind", s.kind, f"a {s.kind} stage cannot follow the {where.kind} "
                                 f"'{where.name}': drive stages come before the differential and half-shafts")
        if role == DIFFERENTIAL:
            if diff >= 0:
                raise ParameterError(f"{label}kind", s.kind, f"second differential; stage {diff + first} "
                                     f"'{stages[diff].name}' is one already")
            if shafts_before:
                raise ParameterError(f"{label}kind", s.kind, "the differential must come before the half-shafts")
            diff = i
        if role == SHAFTS and i != len(stages) - 1:
            raise ParameterError(f"{label}kind", s.kind, "the half-shafts must be the last stage before the wheels")
        if s.right is not None and (diff < 0 or stages[diff].type != "open"):
            raise ParameterError(f"{label}right", "unequal shafts", "two unequal half-shafts need an open "
                                 "differential stage before them")


def split_ends(data: Mapping[str, Any]) -> tuple[dict[str, Any], int]:
    """Move ``kind = "rotor"``/``"wheel"`` entries at the ends of ``stage`` into ``[motor]``/``[wheel]``.

    The chain must run from the rotor to the wheels: the rotor is ``[motor]`` or the first entry,
    the wheel end ``[wheel]`` or the last one; either end missing is an error naming it. Returns
    the data and the file index of the first remaining stage.
    """
    out = dict(data)
    raw = list(out.get("stage", []))
    if not isinstance(out.get("stage"), list) or not raw:
        return out, 0  # parse_chain names the problem
    first = 1 if raw and isinstance(raw[0], Mapping) and raw[0].get("kind") == "rotor" else 0
    for kind, table in END_TABLES.items():
        idx = [i for i, s in enumerate(raw) if isinstance(s, Mapping) and s.get("kind") == kind]
        end = 0 if kind == "rotor" else len(raw) - 1
        for i in idx:
            if i != end:
                name = raw[i].get("name", kind)
                raise ParameterError(f"{_label(i, name)}kind", kind, f"the {kind} must be the "
                                     f"{'first' if kind == 'rotor' else 'last'} entry of the chain")
            if table in out:
                raise ParameterError(f"{_label(i, raw[i].get('name', kind))}kind", kind,
                                     f"given both as a stage and as [{table}]; keep one")
            out[table] = {k: v for k, v in raw[i].items() if k not in ("kind", "name")}
        if not idx and table not in out:
            last = raw[end] if raw and isinstance(raw[end], Mapping) else {}
            at = end + (len(data["stage"]) - len(raw))  # the file's index
            raise ParameterError(f"{_label(at, last.get('name', last.get('kind', '?')))}kind" if raw else "stage",
                                 last.get("kind"),
                                 f"the chain has no {kind} end: add a [{table}] table or a "
                                 f"{'first' if kind == 'rotor' else 'last'} [[stage]] with kind = \"{kind}\"")
        if idx:
            raw = [s for i, s in enumerate(raw) if i not in idx]
    out["stage"] = raw
    return out, first


def stage_dict(s: Stage) -> dict[str, Any]:
    """The stage as a plain table that :func:`parse_stage` reads back (defaults of its kind left out)."""
    out: dict[str, Any] = {"kind": s.kind, "name": s.name}
    for key in s.spec.written_fields(s):
        value = getattr(s, key)
        out[key] = dataclasses.asdict(value) if isinstance(value, Gap) else value
    if s.right is not None:
        out["right"] = {k: (dataclasses.asdict(v) if isinstance(v, Gap) else v)
                        for k, v in dataclasses.asdict(s.right).items()}
        out["right"]["lash_rad"] = dataclasses.asdict(s.right.lash_rad)
    return out


def gap_table(data: dict[str, Any], name: str) -> dict[str, Any]:
    """The dict of gap ``name`` inside :meth:`Vehicle.to_dict` output (stage tables keyed by name)."""
    if "gaps" in data:
        return data["gaps"][name]
    stages = data["stage"]
    if name in stages:
        return stages[name]["lash_rad"]
    return stages[name.removesuffix("_right")]["right"]["lash_rad"]
