"""Identify the paper's unpublished inputs: the tip-in ramp, the five gap sizes and three compliances.

The paper publishes its results (Sections 2.3 and 4: unloaded times, peak-to-valley speed
fluctuations, the speed rise, the gap-removal results and S1..S5) but not the measured torque
trace, the gap sizes or the stiffnesses. :func:`fit` fits all of them **together** to every one
of those figures at once: one weighted least-squares cost over the rows of
:func:`sim.paper.paper_rows`, each residual on the row's own quantity, minimised by
``scipy.optimize.differential_evolution`` (bounded, seeded: the same seed gives the same
result) followed by a bounded Powell polish. :func:`fitted_toml` writes the result as a preset
file whose header says what was fitted to what (``sim/presets/paper_fitted.toml``).

Parameters and bounds (:data:`PARAMS`): the ramp stays within what the paper's text and
figures allow (regeneration at -20..-100 N m before, 80..300 N m after, a 160 kW motor; the ramp
0.05..0.5 s); each gap 0.3..2.5 x the ``paper`` preset's nominal (own-shaft angle); the
half-shaft stiffness and damping and the housing mount stiffness within a factor of two to
three of the preset. Everything else stays the ``paper`` preset's.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution, minimize

from sim.errors import InstabilityError, ParameterError
from sim.paper import (
    PAPER_FLUCT_RPM,
    PAPER_GAPS45_PCT,
    PAPER_GAPS123_PCT,
    PAPER_RISE_RPM,
    PAPER_SENSITIVITY,
    PAPER_UNLOADED_MS,
    TOL_FLUCT,
    TOL_MS,
    TipIn,
    paper_cases,
    sensitivities,
)
from sim.params import Vehicle
from sim.vehicle_file import dump_toml

S_WEIGHT = 0.25


@dataclass(frozen=True)
class Param:
    """One fitted input: ``field`` is a dotted vehicle field or ``tip_in.<field>``; ``log``: fitted in log scale."""

    field: str
    lo: float
    hi: float
    log: bool

    def value(self, u: float) -> float:
        return self.lo * (self.hi / self.lo) ** u if self.log else self.lo + (self.hi - self.lo) * u

    def unit(self, x: float) -> float:
        return math.log(x / self.lo) / math.log(self.hi / self.lo) if self.log else (x - self.lo) / (self.hi - self.lo)


def default_params(base: Vehicle) -> tuple[Param, ...]:
    """The fitted inputs and their bounds around the ``base`` vehicle (the ``paper`` preset)."""
    gaps = tuple(Param(f"gaps.{g}", 0.3 * base.gap(g).nominal, 2.5 * base.gap(g).nominal, True)
                 for g in base.gap_names)
    return (Param("tip_in.start_nm", -100.0, -20.0, False), Param("tip_in.end_nm", 80.0, 300.0, False),
            Param("tip_in.ramp_s", 0.05, 0.5, True), *gaps,
            Param("halfshaft.stiffness", 4000.0, 16000.0, True), Param("halfshaft.damping", 8.0, 100.0, True),
            Param("housing.mount_stiffness", 3.0e4, 3.0e5, True))


def apply(base: Vehicle, params: tuple[Param, ...], x: np.ndarray) -> tuple[Vehicle, TipIn]:
    """The vehicle and tip-in for parameter values ``x`` (physical units)."""
    tip = {p.field.split(".", 1)[1]: float(v) for p, v in zip(params, x, strict=True) if p.field.startswith("tip_in.")}
    changes = {p.field: float(v) for p, v in zip(params, x, strict=True) if not p.field.startswith("tip_in.")}
    return base.with_changes(changes), TipIn(**tip)


def residuals(vehicle: Vehicle, tip_in: TipIn) -> dict[str, float]:
    """Each paper figure's residual on its own quantity, scaled so that 1 = the edge of its target.

    Fluctuations and the speed rise: ``log(ours/paper) / log(1.15)``; times: ``(ours - paper) /
    band``; gaps 4+5 and 1+2+3 removed: percentage points / 5; gap i removed: only the excess over
    10 rpm counts (/ 5 rpm); S1..S4 per arc-minute: ``log(ours/paper) / log(1.5)`` at weight
    :data:`S_WEIGHT` (a non-positive S counts as 1/100 of the paper's). The low weight is a choice:
    no lumped chain can give S3 < S4 < S5 for three gaps at the same shaft speed (tested with and
    without the housing and half-shaft segments), so at full weight these unreachable rows would
    pull the gap sizes away from every figure the model can reproduce.
    """
    c = paper_cases(vehicle, tip_in, twin=False)
    nom = c["nominal"]
    r: dict[str, float] = {}
    for key in ("nominal", "half_gaps", "half_torque"):
        r[f"time_{key}"] = (c[key].unloaded_ms - PAPER_UNLOADED_MS[key]) / TOL_MS[key]
        r[f"fluct_{key}"] = math.log(max(c[key].fluct_rpm, 1.0) / PAPER_FLUCT_RPM[key]) / math.log(1 + TOL_FLUCT)
    r["rise"] = math.log(max(nom.rise_rpm, 1.0) / PAPER_RISE_RPM) / math.log(1 + TOL_FLUCT)
    r["gaps45"] = (100 * c["gaps45"].fluct_rpm / nom.fluct_rpm - PAPER_GAPS45_PCT) / 5.0
    r["gaps123"] = (100 * c["gaps123"].fluct_rpm / nom.fluct_rpm - PAPER_GAPS123_PCT) / 5.0
    for i in (1, 2, 3):
        r[f"gap{i}"] = max(0.0, abs(nom.fluct_rpm - c[f"no_gap{i}"].fluct_rpm) - 10.0) / 5.0
    s = sensitivities(vehicle, c, per="arcmin", quantity="fluctuation")
    for i in range(4):
        p = PAPER_SENSITIVITY[i]
        r[f"S{i + 1}"] = S_WEIGHT * math.log(max(s[i], 0.01 * p) / p) / math.log(1.5)
    return r


def cost(vehicle: Vehicle, tip_in: TipIn) -> float:
    return float(sum(v * v for v in residuals(vehicle, tip_in).values()))


@dataclass(frozen=True)
class FitResult:
    params: tuple[Param, ...]
    x: np.ndarray  # physical values, in params order
    cost: float
    evaluations: int
    vehicle: Vehicle
    tip_in: TipIn


def fit(base: Vehicle, *, seed: int = 0, popsize: int = 6, maxiter: int = 12, polish_evals: int = 150,
        params: tuple[Param, ...] | None = None, progress: Callable[[int, float], None] | None = None) -> FitResult:
    """Differential evolution over the unit cube of :func:`default_params`, then a bounded Powell polish.

    Deterministic for a given ``seed`` (``workers=1``, Latin-hypercube start from the seed, with
    the base vehicle and the default ramp as one member of the first population).
    A parameter set that the validator refuses or that diverges costs 1e6.
    """
    ps = params or default_params(base)
    count = 0
    best = [math.inf]
    best_u = [np.zeros(len(ps))]

    def f(u: np.ndarray) -> float:
        nonlocal count
        count += 1
        x = np.array([p.value(float(np.clip(ui, 0.0, 1.0))) for p, ui in zip(ps, u, strict=True)])
        try:
            v, tip = apply(base, ps, x)
            val = cost(v, tip)
        except (ParameterError, InstabilityError):
            val = 1e6
        if val < best[0]:
            best[0], best_u[0] = val, np.clip(np.asarray(u, dtype=np.float64), 0.0, 1.0)
        if progress is not None and count % 50 == 0:
            progress(count, best[0])
        return val

    bounds = [(0.0, 1.0)] * len(ps)
    start = _start(base, ps)
    de = differential_evolution(f, bounds, seed=seed, popsize=popsize, maxiter=maxiter, polish=False,
                                init="latinhypercube", tol=1e-3, workers=1, updating="immediate", x0=start)
    minimize(f, de.x, method="Powell", bounds=bounds, options={"maxfev": polish_evals, "xtol": 1e-3})
    u = best_u[0]  # the best point evaluated (DE or polish)
    x = np.array([p.value(float(np.clip(ui, 0.0, 1.0))) for p, ui in zip(ps, u, strict=True)])
    v, tip = apply(base, ps, x)
    return FitResult(ps, x, cost(v, tip), count, v, tip)


def _with_scaled_bands(result: FitResult, base: Vehicle) -> Vehicle:
    d = result.vehicle.to_dict()
    for p, x in zip(result.params, result.x, strict=True):
        if p.field.startswith("tip_in."):
            continue
        f = float(x) / float(base.get(p.field))
        if p.field.startswith("gaps."):
            g, b = d["gaps"][p.field[5:]], base.gap(p.field[5:])
            g["min"], g["max"] = b.min * f, b.max * f
        elif p.field in d["tolerances"]:
            lo, hi = base.tolerances[p.field]
            d["tolerances"][p.field] = [lo * f, hi * f]
    return Vehicle.from_dict(d)


def _start(base: Vehicle, ps: tuple[Param, ...]) -> np.ndarray:
    """The starting point in the unit cube: the base vehicle's values and the default ramp (clipped to the bounds)."""
    tip = TipIn()
    vals = [getattr(tip, p.field.split(".", 1)[1]) if p.field.startswith("tip_in.") else float(base.get(p.field))
            for p in ps]
    return np.clip([p.unit(v) for p, v in zip(ps, vals, strict=True)], 0.0, 1.0)


def fitted_toml(result: FitResult, summary: str, base_vehicle: Vehicle) -> str:
    """The preset file: a header saying what was fitted to what, the vehicle, and its ``[tip_in]``.

    Gap bands and ``[tolerances]`` of fitted fields keep their relative width around the fitted
    value (``base_vehicle``'s band times fitted / base), so a tolerance analysis on the fitted
    preset samples around the fit, not around the values it replaced.
    """
    head = [
        "# FITTED, not measured: the `paper` preset with the reference paper's unpublished inputs identified",
        "# by sim/paper_fit.py (bench/paper_fit.py) against ALL of the paper's published figures at once",
        "# (Deng et al. 2022, Sections 2.3 and 4: unloaded times 20/13/26 ms, peak-to-valley fluctuations",
        "# 231/145/186 rpm, speed rise 180 rpm, gaps 1..3 removed < 10 rpm each and ~95 % together, gaps 4+5",
        "# removed ~18 %, S1..S4 per arc-minute). Fitted, with bounds (everything else = the paper preset):",
    ]
    for p, x in zip(result.params, result.x, strict=True):
        head.append(f"#   {p.field:<26} = {x:<12.6g} bounds [{p.lo:.4g}, {p.hi:.4g}]{' (log)' if p.log else ''}")
    head += [f"# cost {result.cost:.4g} after {result.evaluations} evaluations; rows at the fit:"]
    head += [f"#   {line}" for line in summary.splitlines()]
    tip = result.tip_in
    body = dump_toml(_with_scaled_bands(result, base_vehicle).with_changes(
        {"name": "paper_fitted", "description": "Deng et al. 2022 drive unit, unpublished inputs fitted to the "
                                                "paper's figures (see header)"}))
    tail = ["", "[tip_in]                     # the fitted tip-in torque (sim.paper.TipIn), read by reproduce-paper",
            f"start_nm = {tip.start_nm!r}", f"end_nm = {tip.end_nm!r}", f"ramp_s = {tip.ramp_s!r}",
            f"t0_s = {tip.t0_s!r}"]
    return "\n".join(head) + "\n" + body + "\n".join(tail) + "\n"
