"""Vehicle TOML files: load a preset or a path, parse text, write a vehicle back as TOML.

Layout (see ``sim/presets/paper.toml`` for a documented example)::

    name = "..."
    [motor]        rotor_inertia, viscous_damping, max_power_kw
    [reducer]      teeth = [z1, z2, z3, z4], shaft inertias, per-coupling stiffness/damping
    [halfshaft]    stiffness, damping, inertia (per shaft), segments, count
    [wheel]        inertia (per wheel, own), radius
    [body]         mass, speed_kmh, rolling_resistance, drag_area, air_density, grade_percent, brake_torque
    [housing]      enabled, inertia, mount_stiffness, mount_damping
    [gaps.<name>]  nominal, min, max      (total clearance, rad, own shaft angle), radius_mm (contact
                   radius); or nominal_mm, min_mm, max_mm (circumferential clearance) with radius_mm
    [effects.*]    optional effects, all off by default: torque_lag, speed_sensor, drag,
                   progressive_stiffness (cubic terms), tyre_slip (enabled, slip_stiffness, relaxation_length)
    [tolerances]   "section.field" = [min, max]

or, instead of [reducer], [halfshaft] and [gaps.*], the driveline as a chain of stages from the
rotor to the wheels (``sim.stages``; the presets ``single_reduction`` and ``chain_drive`` are
documented examples)::

    [[stage]]      kind (spline, gear, planetary, chain, differential, halfshaft), name, ratio or teeth,
                   stiffness, damping, lash_rad, cubic_stiffness (output shaft angle), inertia (output body)

A stage file without [housing] has no housing on mounts; a classic file without it keeps the
default housing (enabled), as it always had.
"""

from __future__ import annotations

import json
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from sim.errors import ParameterError
from sim.params import Vehicle


def preset_names() -> list[str]:
    """Names of the TOML presets shipped in ``sim/presets``."""
    root = resources.files("sim") / "presets"
    return sorted(p.name[:-5] for p in root.iterdir() if p.name.endswith(".toml"))


def load_vehicle(name_or_path: str | Path) -> Vehicle:
    """A preset by name (``"paper"``) or a TOML file path.

    Raises
    ------
    ParameterError
        Unknown preset/missing file (field ``vehicle``) or an invalid field (named with its value).
    """
    text: str
    source = str(name_or_path)
    if isinstance(name_or_path, str) and name_or_path in preset_names():
        text = (resources.files("sim") / "presets" / f"{name_or_path}.toml").read_text(encoding="utf-8")
    else:
        path = Path(name_or_path)
        if not path.is_file():
            raise ParameterError("vehicle", source, f"neither a preset ({', '.join(preset_names())}) nor a file")
        text = path.read_text(encoding="utf-8")
    return load_vehicle_text(text, source=source)


def load_vehicle_text(text: str, *, source: str = "<text>") -> Vehicle:
    """Parse TOML (or JSON, if the text starts with ``{``) into a validated :class:`Vehicle`."""
    try:
        data = json.loads(text) if text.lstrip().startswith("{") else tomllib.loads(text)
    except (tomllib.TOMLDecodeError, json.JSONDecodeError) as exc:
        raise ParameterError("vehicle", source, f"not valid TOML/JSON: {exc}") from exc
    if isinstance(data, dict):
        data.pop("tip_in", None)  # the torque input a fitted file was identified with (sim.paper.load_tip_in)
        data.pop("provenance", None)  # what an identified file was identified from (lashscope identify)
    return Vehicle.from_dict(data)


def dump_toml(vehicle: Vehicle) -> str:
    """TOML text that :func:`load_vehicle_text` reads back to an equal vehicle."""
    data = vehicle.to_dict()
    lines: list[str] = []
    stages = data.pop("stage", [])
    for key, value in data.items():
        if not isinstance(value, dict):
            lines.append(f"{key} = {toml_value(value)}")
    _tables(data, [], lines)
    for stage in stages:  # the chain in order, rotor side first; sub-tables written inline
        lines += ["", "[[stage]]", *(f"{_key(k)} = {toml_value(v)}" for k, v in stage.items())]
    return "\n".join(lines) + "\n"


def _tables(data: dict[str, Any], prefix: list[str], lines: list[str]) -> None:
    for key, value in data.items():
        if not isinstance(value, dict):
            continue
        path = [*prefix, key]
        scalars = {k: v for k, v in value.items() if not isinstance(v, dict)}
        if scalars or not value:
            lines.append("")
            lines.append(f"[{'.'.join(path)}]")
            for k, v in scalars.items():
                lines.append(f"{_key(k)} = {toml_value(v)}")
        _tables(value, path, lines)


def _key(k: str) -> str:
    return k if k.replace("_", "").isalnum() else json.dumps(k)


def toml_value(v: Any) -> str:
    """``v`` as an inline TOML value (numbers, strings, booleans, lists and tables of them)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ParameterError("vehicle", v, "cannot write a non-finite number")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list | tuple):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise ParameterError("vehicle", v, f"cannot write a {type(v).__name__} to TOML")
