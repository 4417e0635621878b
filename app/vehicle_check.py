"""A cheap trial of a driveline before it is accepted: can the simulator run it at a sane cost?

Loading a driveline checks its values one by one; a value can still be legal and absurd
(``mesh2_stiffness = 1e30``), making the stiffest mode so fast that the integrator step
collapses and one simulated second needs more steps than any analysis could afford. The
trial builds the chain and asks the simulator for its step at the analysis' 1 ms output grid
(:func:`sim.simulate.choose_step`, no integration), and rejects the vehicle when a simulated
second needs more than :data:`MAX_STEPS_PER_S` steps, naming the fields furthest from the
paper preset as the likely cause.
"""

from __future__ import annotations

import math
import tomllib
from typing import Any

from sim import ParameterError, SimError, Vehicle, dump_toml, load_vehicle
from sim.simulate import choose_step

MAX_STEPS_PER_S = 1_000_000  # the paper preset needs 15 000; a 30-min log at this cost is ~2e9 steps
TRIAL_TORQUE_NM = 400.0  # progressive springs are judged at the deflection this torque causes
OUTLIER_FACTOR = 1e3  # a field this far (either way) from the paper preset is named as suspect


def _flat(doc: dict[str, Any], prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for k, v in doc.items():
        key = f"{prefix}{k}"
        if isinstance(v, dict):
            out.update(_flat(v, key + "."))
        elif isinstance(v, int | float) and not isinstance(v, bool):
            out[key] = float(v)
    return out


def _flat_vehicle(vehicle: Vehicle, stage_key: Any = None) -> dict[str, float]:
    """Numeric fields of ``vehicle`` by dotted path; ``[[stage]]`` fields as ``stage.<name>.<field>``
    (``stage_key(stage) -> name`` renames the stage, to look up its counterpart)."""
    doc = tomllib.loads(dump_toml(vehicle))
    out = _flat({k: v for k, v in doc.items() if k != "stage"})
    for st in doc.get("stage", []):
        name = stage_key(st) if stage_key is not None else st["name"]
        out.update(_flat({k: v for k, v in st.items() if k not in ("kind", "name")}, f"stage.{name}."))
    return out


def suspect_fields(vehicle: Vehicle) -> list[tuple[str, float, float]]:
    """Fields (dotted TOML path, value, paper preset value) more than OUTLIER_FACTOR from the preset, worst first.

    Stage files are compared stage by stage with the paper's stage of the same kind."""
    paper = load_vehicle("paper")
    mine = _flat_vehicle(vehicle)
    ref = _flat_vehicle(paper)
    if any(key.startswith("stage.") for key in mine):  # a stage file: compared in its own layout
        paper_stages = _flat_vehicle(paper.as_stages())
        ref.update(paper_stages)
        # each stage against the paper's stage of the same kind (its kind's reference_stage)
        by_kind = {s.name: s.spec.reference_stage for s in vehicle.chain}
        for key in list(mine):
            parts = key.split(".")
            if parts[0] == "stage" and len(parts) >= 3 and parts[1] in by_kind:
                r = paper_stages.get(".".join(["stage", by_kind[parts[1]], *parts[2:]]))
                if r is not None:
                    ref[key] = r
    rows: list[tuple[float, str, float, float]] = []
    for key, v in mine.items():
        r = ref.get(key)
        if r is None or r == 0 or v == 0 or not math.isfinite(v):
            continue
        ratio = abs(v / r)
        if ratio > OUTLIER_FACTOR or ratio < 1 / OUTLIER_FACTOR:
            rows.append((abs(math.log10(ratio)), key, v, r))
    rows.sort(reverse=True)
    return [(k, v, r) for _, k, v, r in rows]


def steps_per_second(vehicle: Vehicle) -> float:
    """Integrator steps one simulated second of the multibody model needs at a 1 ms output grid."""
    _, sub = choose_step(vehicle.compiled, 0.001, torque_max=TRIAL_TORQUE_NM)
    return 1000.0 * sub


def trial_vehicle(vehicle: Vehicle, source: str) -> float:
    """Raise ParameterError naming the suspect field when ``vehicle`` is too costly to simulate; else steps/s.

    ``source`` is the name the user knows the driveline file by.
    """
    try:
        steps = steps_per_second(vehicle)
    except (SimError, OverflowError, ValueError, ZeroDivisionError, FloatingPointError) as exc:
        steps, cause = math.inf, str(exc)
    else:
        cause = ""
        if steps <= MAX_STEPS_PER_S:
            return steps
    suspects = suspect_fields(vehicle)
    if suspects:
        key, v, r = suspects[0]
        field, value = key, v
        hint = f"more than {OUTLIER_FACTOR:g}x {'above' if abs(v) > abs(r) else 'below'} the paper preset's {r:g}"
    else:
        field, value, hint = "driveline", steps, "check the stiffness, damping and inertia values"
    need = "cannot be stepped" if not math.isfinite(steps) else f"needs {steps:.3g} integrator steps per " \
        f"simulated second (limit {MAX_STEPS_PER_S:g})"
    raise ParameterError(field, value, f"driveline {source} {need}{': ' + cause if cause else ''}; {hint}")
