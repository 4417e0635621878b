"""Two vehicle files side by side: what an identification (or an edit) moved.

An identified vehicle (``lashscope identify --out``, ``POST /identifications/{id}/apply``) is the
file's driveline with scaled stiffnesses, dampings, mass and gaps. A list of changed TOML keys
says which fields moved, not what that means for the car, so the comparison leads with the
figures the base parameters are reported as (:func:`app.identify.base.physical`): torsional
stiffness at the motor, the first torsional mode and its damping ratio, vehicle mass, total lash at
the motor, and the torque gain. Then every driveline field that differs (dotted keys, with
``b - a`` and ``b / a`` for numbers), and each file's ``[provenance]`` when it was identified:
the logs it came from, every fitted value with its interval, the residual before and after.

Used by ``lashscope vehicles compare`` and ``GET /vehicles/{name}/compare``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from typing import Any

from app.errors import InputError
from app.identify.base import LABELS, physical
from sim import SimError, Vehicle, load_vehicle_text

# (key, label, unit) of the figures compared, in the order printed
FIGURES: tuple[tuple[str, str, str], ...] = (
    ("stiffness", LABELS["stiffness"], "N m/rad"),
    ("freq", "first torsional mode", "Hz"),
    ("damping", LABELS["damping"], "-"),
    ("mass", LABELS["mass"], "kg"),
    ("lash", LABELS["lash"], "mrad"),
    ("torque_gain", "torque gain (air-gap per logged N m)", "-"),
)
PROVENANCE = "provenance"  # the table an identified file carries; not part of the driveline


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


def _number(x: Any) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool)


def field_change(name: str, a: Any, b: Any) -> dict[str, Any]:
    """One field of both files: ``changed``, and ``delta = b - a``, ``ratio = b / a`` for numbers (None else)."""
    delta = ratio = None
    if _number(a) and _number(b):
        delta = float(b) - float(a)
        ratio = float(b) / float(a) if a and math.isfinite(float(a)) else None
    return {"field": name, "a": a, "b": b, "changed": a != b, "delta": delta, "ratio": ratio}


def figures(vehicle: Vehicle) -> dict[str, float]:
    """The compared figures of one vehicle (NaN where the chain has no oscillating mode)."""
    p = physical(vehicle)
    return {"stiffness": p.stiffness_nm_rad, "freq": p.freq_hz, "damping": p.damping_ratio, "mass": p.mass_kg,
            "lash": p.lash_mrad, "torque_gain": float(vehicle.motor.torque_gain)}


@dataclass
class VehicleComparison:
    """Two vehicle files compared (:func:`compare_texts`); :meth:`to_dict` is the documented JSON."""

    a: str  # labels: what each side is (a file, a registered version, a preset)
    b: str
    figures: list[dict[str, Any]]  # key, label, unit, a, b, ratio
    fields: list[dict[str, Any]]  # every driveline field of either file (see field_change)
    provenance: dict[str, dict[str, Any] | None] = field(default_factory=dict)  # "a"/"b" -> [provenance] or None

    @property
    def changed(self) -> list[dict[str, Any]]:
        return [f for f in self.fields if f["changed"]]

    def to_dict(self) -> dict[str, Any]:
        return {"a": self.a, "b": self.b, "figures": self.figures, "changed": len(self.changed),
                "fields": self.fields, "provenance": self.provenance}


def _parse(text: str, label: str) -> tuple[dict[str, Any], Vehicle]:
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{label}: not a readable TOML file: {exc}", code="invalid_vehicle") from exc
    try:
        vehicle = load_vehicle_text(text)
    except SimError as exc:
        raise InputError(f"{label}: not a valid vehicle file: {exc}", code="invalid_vehicle") from exc
    return doc, vehicle


def compare_texts(text_a: str, text_b: str, label_a: str = "a", label_b: str = "b") -> VehicleComparison:
    """Compare two vehicle files given as TOML text. InputError ``invalid_vehicle`` naming the side that does
    not read as a vehicle file."""
    doc_a, veh_a = _parse(text_a, label_a)
    doc_b, veh_b = _parse(text_b, label_b)
    fig_a, fig_b = figures(veh_a), figures(veh_b)
    figs = []
    for key, label, unit in FIGURES:
        a, b = fig_a[key], fig_b[key]
        ratio = b / a if a and math.isfinite(a) and math.isfinite(b) else None
        figs.append({"key": key, "label": label, "unit": unit, "a": _finite(a), "b": _finite(b), "ratio": ratio})
    prov = {side: d.get(PROVENANCE) if isinstance(d.get(PROVENANCE), dict) else None
            for side, d in (("a", doc_a), ("b", doc_b))}
    flat_a = {k: v for k, v in flatten(doc_a).items() if not k.startswith(PROVENANCE + ".")}
    flat_b = {k: v for k, v in flatten(doc_b).items() if not k.startswith(PROVENANCE + ".")}
    fields = [field_change(k, flat_a.get(k), flat_b.get(k)) for k in sorted(flat_a.keys() | flat_b.keys())]
    return VehicleComparison(label_a, label_b, figs, fields, prov)


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def describe_text(text: str, label: str) -> dict[str, Any]:
    """One vehicle file's figures and ``[provenance]`` (None when it was not identified)."""
    doc, vehicle = _parse(text, label)
    fig = figures(vehicle)
    prov = doc.get(PROVENANCE)
    return {"vehicle": label, "figures": [{"key": k, "label": lab, "unit": unit, "value": _finite(fig[k])}
                                          for k, lab, unit in FIGURES],
            "provenance": prov if isinstance(prov, dict) else None}


def description_lines(desc: dict[str, Any]) -> list[str]:
    """:func:`describe_text` as text."""
    out = [f"vehicle: {desc['vehicle']}", ""]
    out += [f"{_figure_label(f):<42} {_num(f['value']):>12}" for f in desc["figures"]]
    if desc["provenance"]:
        out += ["", *provenance_lines(desc["provenance"])]
    return out


def _figure_label(f: dict[str, Any]) -> str:
    return f"{f['label']} ({f['unit']})" if f["unit"] != "-" else str(f["label"])


def provenance_lines(prov: dict[str, Any]) -> list[str]:
    """An identified file's ``[provenance]`` in a few lines: where from, the fitted values, the residual."""
    logs = prov.get("logs") or []
    out = [f"identified from {prov.get('identified_from', '?')} on {prov.get('date', '?')}, "
           f"{prov.get('events', '?')} events of {len(logs)} log(s): "
           + ", ".join(f"{lg.get('name')} (sha256 {str(lg.get('sha256', ''))[:12]}, {lg.get('events')} events)"
                       for lg in logs)]
    for name, p in (prov.get("fitted") or {}).items():
        if not isinstance(p, dict):
            continue
        lo, hi, value = p.get("lo"), p.get("hi"), p.get("value")
        interval = f" [{lo:.4g}, {hi:.4g}]" if _number(lo) and _number(hi) else ""
        ratio = f"  ({p['ratio']:.2f}x the file's)" if _number(p.get("ratio")) else ""
        shown = f"{value:.4g}" if _number(value) else "-"
        out.append(f"  {name:<10} {shown}{interval} {p.get('unit', '')}{ratio}")
    if prov.get("not_identified"):
        out.append("  not identified (kept at the file's): " + ", ".join(map(str, prov["not_identified"])))
    before, after = prov.get("residual_to_noise_before"), prov.get("residual_to_noise_after")
    if _number(before) and _number(after):
        out.append(f"  residual-to-noise on its events: {before:.3g} -> {after:.3g}")
    return out


def comparison_lines(cmp: VehicleComparison, show_all: bool = False) -> list[str]:
    """The comparison as text: figures, provenance, then the fields that differ (every field with ``show_all``)."""
    out = [f"a: {cmp.a}", f"b: {cmp.b}", "", f"{'figure':<42} {'a':>12} {'b':>12} {'b/a':>8}"]
    for f in cmp.figures:
        ratio = f"{f['ratio']:.3f}x" if f["ratio"] is not None else "-"
        out.append(f"{_figure_label(f):<42} {_num(f['a']):>12} {_num(f['b']):>12} {ratio:>8}")
    for side in ("a", "b"):
        prov = cmp.provenance.get(side)
        if prov:
            out += ["", f"{side}: " + provenance_lines(prov)[0], *provenance_lines(prov)[1:]]
    shown = cmp.fields if show_all else cmp.changed
    out += ["", f"driveline fields: {len(cmp.changed)} of {len(cmp.fields)} differ"
            + ("" if show_all or not cmp.changed else " (--all lists every field)")]
    for f in shown:
        ratio = f"  ({f['ratio']:.3f}x)" if f["ratio"] is not None and f["changed"] else ""
        mark = "*" if f["changed"] else " "
        out.append(f" {mark} {f['field']}: {_num(f['a'])} -> {_num(f['b'])}{ratio}")
    return out


def _num(x: Any) -> str:
    if x is None:
        return "-"
    if _number(x):
        return f"{x:.6g}"
    return str(x)
