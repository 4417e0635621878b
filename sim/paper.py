"""Reproduce the reference paper's Sections 2.3 and 4 with the ``paper`` preset.

Scenario: a tip-in from regeneration to drive at 25 km/h. The paper's measured torque trace is
not published; we use a ramp from ``-50`` to ``+150`` N m over 0.135 s starting at 0.1 s,
sampled at 100 Hz like a CAN torque signal and interpolated linearly.

Metrics (see :mod:`sim.metrics`): unloaded time = first gap opening to last closing; speed
fluctuation = peak to adjacent valley of the resolver speed after the first opening;
impact-induced fluctuation = peak to peak of (speed with gaps - speed without gaps) over the
same window. Sensitivity ``S_i = dn_i / dc_i``: drop of the impact-induced fluctuation when
gap ``i`` is eliminated, per mm of that gap's circumferential clearance (arc at its contact
radius, the paper's measure, so that gear pairs and splines compare), normalised to S5 = 100;
per radian of the gap's own shaft angle as a secondary view.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from sim.errors import ParameterError
from sim.layout import shaft_gap
from sim.metrics import impact_induced_fluctuation, peak_to_valley, unloaded_time
from sim.params import GAP_NAMES, Vehicle
from sim.simulate import SimResult, simulate
from sim.whatif import WhatIf

F64 = NDArray[np.float64]
PAPER_UNLOADED_MS = {"nominal": 20.0, "half_gaps": 13.0, "half_torque": 26.0}
PAPER_FLUCT_RPM = {"nominal": 231.0, "half_gaps": 145.0, "half_torque": 186.0}
PAPER_RISE_RPM = 180.0
PAPER_SENSITIVITY = (0.9, 3.0, 11.0, 36.0, 100.0)
TOL_MS = {"nominal": 3.0, "half_gaps": 3.0, "half_torque": 4.0}
WINDOW_S = 0.35  # metric window after the first gap opening: the shuffle has rung down by then


def tip_in_torque(scale: float = 1.0, rate_hz: float = 100.0, duration_s: float = 0.8) -> tuple[F64, F64]:
    """The tip-in torque samples (s, N m): -50 -> +150 N m ramp over 0.1..0.235 s, times ``scale``."""
    t = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    q = np.interp(t, [0.0, 0.1, 0.235, duration_s], [-50.0, -50.0, 150.0, 150.0]) * scale
    return t, q


@dataclass(frozen=True)
class CaseResult:
    name: str
    unloaded_ms: float
    fluct_rpm: float
    impact_rpm: float
    rise_rpm: float
    result: SimResult


def run_case(vehicle: Vehicle, name: str, what_if: WhatIf | None = None, torque_scale: float = 1.0) -> CaseResult:
    """One case and its zero-gap twin (same torque) for the impact-induced metric."""
    t, q = tip_in_torque(torque_scale)
    res = simulate(vehicle, t, q, interp="linear", what_if=what_if)
    zero = WhatIf(gap_scale={"all": 0.0})
    base_vehicle = what_if.apply_vehicle(vehicle) if what_if is not None else vehicle
    base = simulate(base_vehicle, t, q, interp="linear", what_if=zero)
    opens = [e[1] for e in res.gap_events if e[1] > 0.05]
    t_first = min(opens) if opens else 0.1
    w = (t_first - 0.005, t_first + WINDOW_S)
    ul = unloaded_time(res.gap_events, t_start=0.05)
    k0, k1 = np.searchsorted(res.t, [t_first, t_first + ul])
    rise = float(res.motor_speed_rpm[min(k1, res.t.size - 1)] - res.motor_speed_rpm[k0])
    return CaseResult(
        name=name, unloaded_ms=ul * 1e3,
        fluct_rpm=peak_to_valley(res.t, res.motor_speed_rpm, *w),
        impact_rpm=impact_induced_fluctuation(res.t, res.motor_speed_rpm, base.motor_speed_rpm, *w),
        rise_rpm=rise, result=res,
    )


@dataclass(frozen=True)
class Row:
    quantity: str
    ours: float
    paper: float | str
    target: str
    ok: bool | None  # None: reported, no target

    def __post_init__(self) -> None:  # plain Python types, so rows serialise to JSON as they are
        object.__setattr__(self, "ours", float(self.ours))
        if self.ok is not None:
            object.__setattr__(self, "ok", bool(self.ok))


def reproduce(vehicle: Vehicle) -> tuple[list[Row], dict[str, CaseResult]]:
    """All cases of Sections 2.3 and 4 and the comparison rows with pass/fail per target."""
    cases = {
        "nominal": run_case(vehicle, "nominal"),
        "half_gaps": run_case(vehicle, "half_gaps", WhatIf(gap_scale={"all": 0.5})),
        "half_torque": run_case(vehicle, "half_torque", torque_scale=0.5),
        "gaps45": run_case(vehicle, "gaps45", WhatIf(gap_scale={"differential": 0.0, "halfshaft": 0.0})),
        "zero_gaps": run_case(vehicle, "zero_gaps", WhatIf(gap_scale={"all": 0.0})),
    }
    for i, g in enumerate(GAP_NAMES, start=1):
        cases[f"no_gap{i}"] = run_case(vehicle, f"no_gap{i}", WhatIf(gap_scale={g: 0.0}))
    nom = cases["nominal"]
    rows: list[Row] = []
    for key, label in (("nominal", "nominal gaps"), ("half_gaps", "all gaps halved"), ("half_torque", "torque halved")):
        c = cases[key]
        target, tol = PAPER_UNLOADED_MS[key], TOL_MS[key]
        rows.append(Row(f"unloaded time, {label} (ms)", c.unloaded_ms, target, f"{target:g} +/- {tol:g}",
                        abs(c.unloaded_ms - target) <= tol))
        rows.append(Row(f"fluctuation peak-valley, {label} (rpm)", c.fluct_rpm, PAPER_FLUCT_RPM[key],
                        "reported", None))
        rows.append(Row(f"impact-induced fluctuation, {label} (rpm)", c.impact_rpm, "-", "reported", None))
    rows.append(Row("speed rise while unloaded, nominal (rpm)", nom.rise_rpm, PAPER_RISE_RPM, "reported", None))
    for key, paper_ratio in (("half_gaps", 145.0 / 231.0), ("half_torque", 186.0 / 231.0)):
        ratio = cases[key].fluct_rpm / nom.fluct_rpm
        rows.append(Row(f"fluctuation ratio {key}/nominal", ratio, round(paper_ratio, 2),
                        f"{paper_ratio:.2f} +/- 0.1", abs(ratio - paper_ratio) <= 0.1))
    unit = sensitivity_unit(vehicle)
    sens = sensitivities(vehicle, cases, per=unit)
    ranking_ok = bool(np.all(np.diff(sens) > 0))
    rows.append(Row(f"sensitivity ranking S1<S2<S3<S4<S5 (per {unit})", float(ranking_ok), "yes", "same ranking",
                    ranking_ok))
    for i, (s, p) in enumerate(zip(sens, PAPER_SENSITIVITY, strict=True), start=1):
        ok = p / 1.5 <= s <= p * 1.5 if s > 0 else False
        rows.append(Row(f"S{i} per {unit} of clearance (S5 = 100)", s, p, f"{p / 1.5:.3g}..{p * 1.5:.3g}", ok))
    if unit == "mm":  # secondary view: per radian of each gap's own shaft angle
        rad = sensitivities(vehicle, cases, per="rad")
        rows.append(Row("sensitivity ranking per rad of own-shaft angle", float(np.all(np.diff(rad) > 0)), "-",
                        "reported", None))
    for i in (1, 2, 3):
        d = nom.fluct_rpm - cases[f"no_gap{i}"].fluct_rpm
        rows.append(Row(f"gap {i} eliminated: change in peak-valley (rpm)", d, "< 10", "|change| < 10", abs(d) < 10))
    r45 = cases["gaps45"].impact_rpm / nom.impact_rpm
    rows.append(Row("gaps 4+5 eliminated: impact-induced / nominal (%)", 100 * r45, 18.0, "18 +/- 10",
                    abs(100 * r45 - 18.0) <= 10.0))
    rows.append(Row("gaps 4+5 eliminated: peak-valley / nominal (%)", 100 * cases["gaps45"].fluct_rpm / nom.fluct_rpm,
                    "-", "reported", None))
    rows.append(Row("zero-gap baseline: peak-valley (rpm)", cases["zero_gaps"].fluct_rpm, "-", "reported", None))
    return rows, cases


def sensitivity_unit(vehicle: Vehicle) -> Literal["mm", "rad"]:
    """``"mm"`` when every gap has its contact radius (the paper's definition), else ``"rad"``."""
    return "mm" if all(r > 0 for r in vehicle.gap_radii_mm) else "rad"


def sensitivities(vehicle: Vehicle, cases: dict[str, CaseResult],
                  per: Literal["mm", "rad", "auto"] = "auto") -> F64:
    """S_i = (impact_nominal - impact_without_gap_i) / dc_i, normalised to the half-shaft gap = 100.

    One value per gap in ``vehicle.gap_names`` order (classic layout: five, S5 = halfshaft = 100).

    ``per="mm"``: ``dc_i`` is the gap's circumferential clearance in mm (nominal angle times
    contact radius), the paper's definition; ``per="rad"``: its angle in its own shaft;
    ``"auto"``: mm when every gap has a radius (:func:`sensitivity_unit`), else rad.
    ``cases`` needs ``"nominal"`` and ``"no_gap1"`` .. ``"no_gapN"`` (:func:`run_case`).
    """
    unit = sensitivity_unit(vehicle) if per == "auto" else per
    if unit not in ("mm", "rad"):
        raise ParameterError("per", per, "must be 'mm', 'rad' or 'auto'")
    size = vehicle.gaps_mm if unit == "mm" else tuple(vehicle.gap(g).nominal for g in vehicle.gap_names)
    nom = cases["nominal"].impact_rpm
    raw = np.array([(nom - cases[f"no_gap{i}"].impact_rpm) / max(size[i - 1], 1e-12)
                    for i in range(1, len(vehicle.gap_names) + 1)])
    ref = raw[vehicle.gap_names.index(shaft_gap(vehicle))]
    return 100.0 * raw / ref if ref != 0 else raw


def sensitivity_table(vehicle: Vehicle, cases: dict[str, CaseResult]) -> str:
    """Per-gap detail: sizes, contact radii, S per mm and per rad, and the radius the paper's S_i implies.

    The last column holds every other radius fixed and asks which contact radius of gap ``i``
    would make our S_i (per mm) equal the paper's: ``r_i * S_i / S_i,paper``.
    """
    per_rad = sensitivities(vehicle, cases, per="rad")
    have_mm = sensitivity_unit(vehicle) == "mm"
    per_mm = sensitivities(vehicle, cases, per="mm") if have_mm else np.full(len(GAP_NAMES), np.nan)
    nom = cases["nominal"].impact_rpm
    head = (f"{'gap':<14} {'rad (own)':>9} {'r (mm)':>7} {'arc (mm)':>8} {'motor rad/mm':>12} {'dn (rpm)':>8} "
            f"{'S/mm':>6} {'S/rad':>6} {'paper':>6} {'r for paper S (mm)':>18}")
    lines = [head, "-" * len(head)]
    for i, g in enumerate(GAP_NAMES):
        gap = getattr(vehicle.gaps, g)
        dn = nom - cases[f"no_gap{i + 1}"].impact_rpm
        arc = gap.nominal * gap.radius_mm if have_mm else np.nan
        cost = vehicle.motor_angle_per_mm[i] if have_mm else np.nan
        need = gap.radius_mm * per_mm[i] / PAPER_SENSITIVITY[i] if have_mm else np.nan
        lines.append(f"{i + 1} {g:<12} {gap.nominal:>9.4f} {gap.radius_mm:>7.2f} {arc:>8.3f} {cost:>12.4f} "
                     f"{dn:>8.1f} {per_mm[i]:>6.3g} {per_rad[i]:>6.3g} {PAPER_SENSITIVITY[i]:>6g} {need:>18.3g}")
    return "\n".join(lines)


def format_table(rows: list[Row]) -> str:
    """Plain-text table: quantity, ours, paper, target, PASS/FAIL/-."""
    head = f"{'quantity':<52} {'ours':>9} {'paper':>8}  {'target':<16} result"
    lines = [head, "-" * len(head)]
    for r in rows:
        paper = f"{r.paper:g}" if isinstance(r.paper, float) else str(r.paper)
        verdict = "-" if r.ok is None else ("PASS" if r.ok else "FAIL")
        lines.append(f"{r.quantity:<52} {r.ours:>9.3g} {paper:>8}  {r.target:<16} {verdict}")
    n_t = sum(r.ok is not None for r in rows)
    n_p = sum(bool(r.ok) for r in rows)
    lines.append(f"{n_p}/{n_t} targets met")
    return "\n".join(lines)
