"""Joint bounded least-squares fit of nuisance and effect parameters on calibration events.

Every fit -- the baseline included -- frees the three nuisance parameters (time offset, torque
gain, road load): an unmodelled time offset left out of the baseline is exactly what a prototype
then "explained" as actuator lag. Parameters are mapped to the unit box so that one finite-
difference step (2 % of the prior range) means the same for all of them; the step is coarse on
purpose, because a fixed-step simulator with contact events is only piecewise smooth.

Fits see calibration events only: :func:`fit` takes the frozen :class:`~.split.Split` and refuses
any event that is not on its calibration side.
"""

from __future__ import annotations

import inspect
from collections import Counter, OrderedDict
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy.optimize import least_squares, lsq_linear

from app.analysis.blas_threads import single_blas_thread
from app.analysis.diagnosis import forward
from app.analysis.diagnosis.forward import (
    DiagEvent,
    EffectSetting,
    Nuisance,
    best_offset,
    prediction,
    simulate_events,
    vehicle_with,
    weighted_residual,
)
from app.analysis.diagnosis.split import Split, require_calibration
from app.serial import Rule, Serial, computed, lists, rule
from sim import Vehicle
from sim.effects.base import Effect, ParamSpec
from sim.errors import SimError

FloatArray = npt.NDArray[np.float64]

GAIN_BOUNDS = (0.85, 1.15)
GRADE_BOUNDS_PCT = (-4.0, 4.0)
OFFSET_PERIODS = 2.0  # time offset bounded to +-2 sample periods of the speed channel ...
OFFSET_MIN_S = 0.02  # ... or +-20 ms, whichever is wider: a logger's torque-to-speed offset does not shrink with the
# sampling period (a 1 kHz log offset by 10 ms had its delay taken by the stiffness and the mass)
_PENALTY = 1e3  # residual (noise units) returned for a parameter set the simulator rejects
TRADE_OFF_CORR = 0.9  # |correlation| of two fitted effect parameters above which the data do not separate them
PASSES_PER_PARAM = 12  # a refinement's simulator passes: this x (parameters + 1), finite-difference Jacobians included
# a Jacobian's columns and a screen's start points simulated side by side on the simulation threads (the same
# numbers as one after the other); False: one after the other
PARALLEL_POINTS = True
_LSQ_WORKERS = "workers" in inspect.signature(least_squares).parameters  # scipy >= 1.16
# > 1: the refinement's Jacobian by finite differences only every this many trust-region steps, rank-one (Broyden)
# updates in between (fewer passes, other numbers: off until the decision benchmarks say otherwise)
BROYDEN_EVERY = 0
MEMO_POINTS = 8  # points whose residuals a fit keeps (the simulator is deterministic: same point, same residual)
START_MARGIN = 0.005  # unit-box distance from a bound at which a refinement from a given start begins


@dataclass(frozen=True)
class Bounds:
    """Bounds of the nuisance parameters for one log."""

    offset_s: tuple[float, float]
    gain: tuple[float, float] = GAIN_BOUNDS
    grade_pct: tuple[float, float] = GRADE_BOUNDS_PCT

    @classmethod
    def for_period(cls, period_s: float) -> Bounds:
        half = max(OFFSET_PERIODS * period_s, OFFSET_MIN_S)
        return cls((-half, half))

    def specs(self) -> tuple[ParamSpec, ...]:
        """Nuisance parameters in the least-squares vector (the offset is profiled, not in it)."""
        return (
            ParamSpec("gain", "-", self.gain[0], self.gain[1], 1.0, "torque gain"),
            ParamSpec("grade_pct", "%", self.grade_pct[0], self.grade_pct[1], 0.0, "road-load offset as grade"),
        )


@dataclass(frozen=True)
class FitResult(Serial):
    """Outcome of one fit on the calibration events.

    Attributes
    ----------
    effects : effect ids in the fit (empty for the baseline).
    nuisance : fitted nuisance parameters.
    values : fitted values per effect id.
    chi2 : weighted SSE on the calibration events (noise units); ``n`` its sample count.
    nfev : simulator passes over the calibration events.
    at_bound : ``"<effect>.<param>"`` names that ended within 1 % of a prior bound (not counting an
        effect parameter resting at its ``off`` value).
    """

    effects: tuple[str, ...] = field(metadata=rule(convert=lists))
    nuisance: Nuisance = field(metadata=rule(digits=6))
    values: dict[str, dict[str, float]] = field(metadata=rule(key="params", digits=6))
    chi2: float = field(metadata=rule(skip=True))
    n: int = field(metadata=rule(skip=True))
    nfev: int = field(metadata=rule(key="simulator_passes"))
    at_bound: tuple[str, ...] = field(default=(), metadata=rule(convert=lists))
    message: str = field(default="", metadata=rule(skip=True))
    trade_offs: tuple[tuple[str, str, float], ...] = field(default=(), metadata=rule(convert=lambda t: [
        {"params": [a, b], "correlation": round(r, 4)} for a, b, r in t]))
    settings: tuple[EffectSetting, ...] = field(default=(), repr=False, compare=False, metadata=rule(skip=True))
    # at the solution, for interval estimates: the weighted residual (events in order) and its Jacobian in the
    # unit box (nuisance columns first, then the effects'; None when it was not computed, e.g. the baseline)
    residual: FloatArray | None = field(default=None, repr=False, compare=False, metadata=rule(skip=True))
    jac: FloatArray | None = field(default=None, repr=False, compare=False, metadata=rule(skip=True))

    serial_computed = computed(chi2_per_sample=Rule(key="calibration_chi2_per_sample", digits=4))
    serial_order = ("effects", "nuisance", "values", "chi2_per_sample", "nfev", "at_bound", "trade_offs")

    @property
    def chi2_per_sample(self) -> float:
        return self.chi2 / max(self.n, 1)


Progress = Callable[[str], None]


class StageStarts:
    """End points of one stage's fits, start points of the next stage's (the sequential design, docs/diagnosis.md).

    Stage *k + 1* of a sequential design fits the events of stage *k* and as many again, with the same fits in
    the same order. A fit with effects (a candidate, a pair, a joint refit with the base parameters) is keyed by
    its effects and how many fits with those effects came before it in its stage; the previous stage's fit with
    that key ended where this one most likely ends, so its end point joins the start points (screened with them,
    or an alternative of a refinement from a given start). Only start points change: the refinement, its budget
    and the decision rules are those of a fit without it.
    """

    def __init__(self) -> None:
        self.previous: dict[tuple[tuple[str, ...], int], FitResult] = {}
        self.current: dict[tuple[tuple[str, ...], int], FitResult] = {}
        self.seen: Counter[tuple[str, ...]] = Counter()

    def next_stage(self) -> None:
        self.previous, self.current = self.current, {}
        self.seen.clear()

    def claim(self, effects: tuple[str, ...]) -> tuple[tuple[tuple[str, ...], int], FitResult | None]:
        key = (effects, self.seen[effects])
        self.seen[effects] += 1
        return key, self.previous.get(key)


_STAGE_STARTS: ContextVar[StageStarts | None] = ContextVar("lashscope_stage_starts", default=None)


@contextmanager
def stage_starts() -> Iterator[StageStarts]:
    """Fits in this context (this thread's) take the previous stage's end points as start points; call
    :meth:`StageStarts.next_stage` between stages."""
    memory = StageStarts()
    token = _STAGE_STARTS.set(memory)
    try:
        yield memory
    finally:
        _STAGE_STARTS.reset(token)


class _Problem:
    """Maps a unit-box vector to nuisance + effect values and evaluates calibration residuals.

    The vector holds gain, road load and the effect parameters; the time offset is profiled out
    for every evaluation (:func:`~.forward.best_offset`).
    """

    N_NUISANCE = 2

    def __init__(self, base: Vehicle, events: Sequence[DiagEvent], effects: Sequence[Effect], bounds: Bounds,
                 model: str) -> None:
        self.base = base
        self.events = tuple(events)
        self.effects = tuple(effects)
        self.model = model
        self.bounds = bounds
        self.specs: list[ParamSpec] = list(bounds.specs())
        self.owner: list[str] = ["nuisance"] * self.N_NUISANCE
        for eff in self.effects:
            self.specs.extend(eff.params)
            self.owner.extend([eff.id] * len(eff.params))
        self.lo = np.array([p.lo for p in self.specs])
        self.span = np.array([p.hi - p.lo for p in self.specs])
        self.n_res = sum(e.n for e in self.events)
        self.nfev = 0
        self.last_offset = 0.0
        self.max_passes: int | None = None  # simulator passes before the refinement stops (see _Spent)
        self.best: tuple[float, FloatArray, float] | None = None  # (chi2, u, offset) of the best pass so far
        # residual and offset of the last few points, by their bytes: a point met again is not simulated again
        self._memo: OrderedDict[bytes, tuple[FloatArray, float]] = OrderedDict()
        self._ahead: dict[bytes, tuple[FloatArray, float] | None] = {}  # points run ahead (run_ahead), by their bytes

    def decode(self, u: FloatArray, offset: float = 0.0) -> tuple[Nuisance, tuple[EffectSetting, ...]]:
        x = self.lo + np.clip(u, 0.0, 1.0) * self.span
        nui = Nuisance(offset, float(x[0]), float(x[1]))
        settings: list[EffectSetting] = []
        i = self.N_NUISANCE
        for eff in self.effects:
            k = len(eff.params)
            settings.append((eff, eff.values([float(v) for v in x[i:i + k]])))
            i += k
        return nui, tuple(settings)

    def encode(self, nui: Nuisance, values: dict[str, dict[str, float]] | None = None) -> FloatArray:
        x = [nui.gain, nui.grade_pct]
        for eff in self.effects:
            given = (values or {}).get(eff.id, {})
            x.extend(given.get(p.name, p.off) for p in eff.params)
        return np.asarray(np.clip((np.array(x) - self.lo) / self.span, 0.0, 1.0), dtype=np.float64)

    def residuals(self, u: FloatArray) -> FloatArray:
        if self.max_passes is not None and self.nfev >= self.max_passes:
            raise _Spent
        self.nfev += 1  # a repeated point counts too: the pass budget, and so the refinement, stay as they were
        key = np.asarray(u, dtype=np.float64).tobytes()
        hit = self._memo.get(key)
        if hit is not None:  # the same point again (the solution after the refinement, a start screened twice)
            self.last_offset = hit[1]
            return self._scored(u, hit[0].copy())
        got = self._ahead.pop(key) if key in self._ahead else self._evaluate(u)
        if got is None:
            return np.full(self.n_res, _PENALTY)
        r, self.last_offset = got
        self._memo[key] = (r.copy(), self.last_offset)
        while len(self._memo) > MEMO_POINTS:
            self._memo.popitem(last=False)
        return self._scored(u, r)

    def _evaluate(self, u: FloatArray, threads: bool = True) -> tuple[FloatArray, float] | None:
        """One simulator pass at ``u``: the weighted residual (non-finite values as the penalty) and the profiled
        offset; None when the simulator rejects the parameters. No state of the problem changes here."""
        nui, settings = self.decode(u)
        try:
            veh = vehicle_with(self.base, nui, settings)
            outs = simulate_events(self.events, veh, nui.gain, settings, self.model, gaps=False, threads=threads)
        except SimError:
            return None
        offset = best_offset(self.events, outs, self.bounds.offset_s)
        r = np.concatenate([weighted_residual(ev, prediction(ev, out, offset))
                            for ev, out in zip(self.events, outs, strict=True)])
        return np.where(np.isfinite(r), r, _PENALTY), offset

    def run_ahead(self, points: Sequence[FloatArray]) -> None:
        """Simulate ``points`` side by side on the simulation threads (each point's clusters in one thread) before
        :meth:`residuals` takes them in order: a Jacobian's columns, the start points of a screen.

        Only the points the pass budget will let :meth:`residuals` reach are run; the state of the problem (pass
        count, best point, offset, memo) changes only in :meth:`residuals`, in the caller's order, so every
        number is the one the points evaluated one after the other give.
        """
        if not PARALLEL_POINTS or forward.SIM_THREADS < 2:
            return
        room = len(points) if self.max_passes is None else max(self.max_passes - self.nfev, 0)
        todo: dict[bytes, FloatArray] = {}
        for p in points[:room]:
            key = np.asarray(p, dtype=np.float64).tobytes()
            if key not in self._memo and key not in self._ahead:
                todo[key] = np.array(p, dtype=np.float64)
        if len(todo) < 2:
            return
        results = forward.sim_pool().map(lambda p: self._evaluate(p, threads=False), todo.values())
        self._ahead.update(zip(todo, results, strict=True))

    def ahead_map(self, fun: Callable[[FloatArray], Any], points: Iterable[FloatArray]) -> list[Any]:
        """``map`` for the finite-difference Jacobian of ``least_squares`` (its ``workers``): the columns' points run
        ahead side by side, then ``fun`` (scipy's wrapper of :meth:`residuals`) takes each in order."""
        pts = list(points)
        self.run_ahead(pts)
        try:
            return [fun(p) for p in pts]
        finally:
            self._ahead.clear()

    def peek(self, u: FloatArray) -> FloatArray | None:
        """The residual of a point in the memo (a copy), without counting a pass; None when it is not there."""
        hit = self._memo.get(np.asarray(u, dtype=np.float64).tobytes())
        return None if hit is None else hit[0].copy()

    def _scored(self, u: FloatArray, r: FloatArray) -> FloatArray:
        c2 = _chi2(r)
        if self.best is None or c2 < self.best[0]:
            self.best = (c2, np.array(u, dtype=np.float64), self.last_offset)
        return r

    def jacobian(self, u: FloatArray, r: FloatArray, step: float = 0.02) -> FloatArray:
        """Forward-difference Jacobian at ``u`` (unit box, steps away from the nearer bound; the columns' points
        simulated side by side, :meth:`run_ahead`)."""
        steps, points = [], []
        for k in range(u.size):
            du = step if u[k] <= 0.5 else -step
            v = u.copy()
            v[k] += du
            steps.append(du)
            points.append(v)
        self.run_ahead(points)
        try:
            return np.column_stack([(self.residuals(v) - r) / du for v, du in zip(points, steps, strict=True)])
        finally:
            self._ahead.clear()


class _Broyden:
    """Jacobian for ``least_squares``: a forward-difference one every ``every``-th call, rank-one (Broyden) updates
    from the residual change of the step in between (no simulator pass). Off by default (:data:`BROYDEN_EVERY`)."""

    def __init__(self, prob: _Problem, every: int) -> None:
        self.prob, self.every = prob, every
        self.calls = 0
        self.fresh = False  # the last Jacobian returned was a finite-difference one
        self.state: tuple[FloatArray, FloatArray, FloatArray] | None = None  # (x, f, J) of the last call

    def __call__(self, x: FloatArray) -> FloatArray:
        x = np.asarray(x, dtype=np.float64)
        f = self.prob.peek(x)
        if f is None:
            f = self.prob.residuals(x)
        if self.state is None or self.calls % self.every == 0:
            jac = self.prob.jacobian(x, f)
            self.fresh = True
        else:
            x0, f0, j0 = self.state
            dx = x - x0
            den = float(dx @ dx)
            jac = j0 + np.outer((f - f0) - j0 @ dx, dx) / den if den > 0 else j0
            self.fresh = False
        self.calls += 1
        self.state = (x.copy(), f.copy(), jac)
        return jac


class _Spent(Exception):
    """The refinement used up its simulator passes (``_Problem.max_passes``)."""


def trade_offs(jac: FloatArray, names: Sequence[str], owners: Sequence[str],
               limit: float = TRADE_OFF_CORR) -> tuple[tuple[str, str, float], ...]:
    """Pairs of effect parameters the calibration data cannot separate: ``(a, b, correlation)``.

    The correlation comes from the Gauss-Newton covariance ``(J^T J)^-1`` at the solution (unit-box
    parameters, nuisance included so that a trade-off through the road load or gain counts too).
    Near +-1 one parameter can stand in for the other: a lash split between the reducer and the
    half-shaft whose total is all the traverse time measures, an input lag against an output filter.
    """
    j = np.asarray(jac, dtype=np.float64)
    if j.ndim != 2 or j.shape[1] < 2 or not np.all(np.isfinite(j)):
        return ()
    cov = np.linalg.pinv(j.T @ j)
    var = np.diag(cov)
    # a parameter the pseudo-inverse gives no variance (its column is zero: the data do not move with it) has no
    # correlation to report; elsewhere rounding cannot take a correlation past +-1
    seen = var > 1e-12 * max(float(var.max()), 1e-300)
    d = np.sqrt(np.where(seen, var, 1.0))
    corr = np.clip(np.where(np.outer(seen, seen), cov / np.outer(d, d), 0.0), -1.0, 1.0)
    out = []
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            if owners[a] != "nuisance" and owners[b] != "nuisance" and abs(corr[a, b]) >= limit:
                out.append((f"{owners[a]}.{names[a]}", f"{owners[b]}.{names[b]}", float(corr[a, b])))
    return tuple(out)


def _chi2(r: FloatArray) -> float:
    return float(np.dot(r, r))


def _starts(effects: Sequence[Effect], rng: np.random.Generator, n_random: int) -> list[FloatArray]:
    """Unit-box start points for the effect parameters: near 'off', the middle, a few others.

    Starts sit slightly inside the box: the trust-region method scales steps by the distance to a
    bound and would barely move a parameter that starts exactly on one.
    """
    k = sum(len(e.params) for e in effects)
    if k == 0:
        return [np.zeros(0)]
    off = np.concatenate([[(p.off - p.lo) / (p.hi - p.lo) for p in e.params] for e in effects])
    pts = [np.full(k, 0.5), np.clip(off, 0.03, 0.97), np.full(k, 0.2), np.full(k, 0.8)]
    pts.extend(rng.uniform(0.05, 0.95, size=(n_random, k)))
    return [np.asarray(p, dtype=np.float64) for p in pts]


@single_blas_thread()  # also for callers outside a diagnosis (identification): see app/analysis/blas_threads.py
def fit(
    base: Vehicle,
    events: Sequence[DiagEvent],
    split: Split,
    effects: Sequence[Effect] = (),
    *,
    bounds: Bounds,
    model: str = "multibody",
    start: FitResult | None = None,
    max_nfev: int | None = None,
    n_random_starts: int = 1,
    screen: bool = True,
    alternatives: Sequence[dict[str, dict[str, float]] | FitResult] = (),
    max_passes: int | None = None,
    passes_per_param: int = PASSES_PER_PARAM,
    seed: int = 0,
) -> FitResult:
    """Fit nuisance (+ effect) parameters on the calibration events of ``split``.

    Parameters
    ----------
    base : the diagnosed vehicle (what the model says without any candidate effect).
    events : calibration events; any held-out event raises :class:`~app.errors.AnalysisError`.
    split : the frozen split.
    effects : candidate effects fitted jointly (empty: the baseline calibration).
    bounds : nuisance bounds.
    model : simulator model name.
    start : a previous fit whose nuisance (and effect values) seed this one.
    max_nfev : budget of residual evaluations for the local refinement.
    n_random_starts : random effect-parameter start points screened besides the fixed ones.
    screen : screen the fixed and random start points; False: refine from ``start`` (it must hold
        values for every effect), or from the best of it and ``alternatives`` (effect values with the start's
        nuisance, or fits whose own nuisance and values are the start point).
    max_passes : simulator passes of the refinement, Jacobians included (None: ``passes_per_param``
        x (parameters + 1)); when they run out the best point seen is the result.
    passes_per_param : see ``max_passes``.
    seed : RNG seed of the random start points.

    Inside :func:`stage_starts` (a staged diagnosis or identification) a fit with effects also screens the end point
    of the previous stage's fit with the same effects and the same place in its stage (:class:`StageStarts`).
    """
    require_calibration(split, events)
    prob = _Problem(base, events, effects, bounds, model)
    rng = np.random.default_rng(seed)
    memory = _STAGE_STARTS.get() if effects else None
    key, warm = memory.claim(tuple(e.id for e in effects)) if memory is not None else (None, None)
    nui0 = start.nuisance if start is not None else Nuisance()
    u_nui = prob.encode(nui0)[:prob.N_NUISANCE]
    candidates: list[FloatArray] = []
    if not effects:
        candidates.append(u_nui)
    else:
        prev = start.values if start is not None else None
        if prev is not None and all(e.id in prev for e in effects):
            candidates.append(prob.encode(nui0, prev))
        elif not screen:
            raise ValueError("fit(screen=False) needs a start with values for every effect")
        if not screen:
            candidates.extend(prob.encode(alt.nuisance, alt.values) if isinstance(alt, FitResult)
                              else prob.encode(nui0, alt) for alt in alternatives)
            for u0 in candidates:  # a start on a bound barely moves (see _starts)
                u0[prob.N_NUISANCE:] = np.clip(u0[prob.N_NUISANCE:], START_MARGIN, 1.0 - START_MARGIN)
    if effects and screen:
        # the baseline's nuisance values may have soaked up the effect (a road load taking a drag, an
        # offset taking a delay): screen every start with them and with the nominal values
        u_nominal = prob.encode(Nuisance())[:prob.N_NUISANCE]
        for k, eff_u in enumerate(_starts(effects, rng, n_random_starts)):
            candidates.append(np.concatenate([u_nui, eff_u]))
            if k < 4:  # the fixed starts also with nominal nuisance values (a drag start on top of a road load
                # that took the drag in the baseline counts the drag twice and loses the screen)
                candidates.append(np.concatenate([u_nominal, eff_u]))
    if warm is not None:  # the previous stage's end point of this fit joins the start points
        u_warm = prob.encode(warm.nuisance, warm.values)
        u_warm[prob.N_NUISANCE:] = np.clip(u_warm[prob.N_NUISANCE:], START_MARGIN, 1.0 - START_MARGIN)
        candidates.append(u_warm)
    if len(candidates) > 1:
        prob.run_ahead(candidates)
        scored = [(_chi2(prob.residuals(u)), i) for i, u in enumerate(candidates)]
        prob._ahead.clear()
    else:
        scored = [(0.0, 0)]
    best_u = candidates[min(scored)[1]]
    n_par = best_u.size
    budget = max_nfev if max_nfev is not None else 6 * (n_par + 1)
    prob.best = None
    prob.max_passes = prob.nfev + (max_passes if max_passes is not None else passes_per_param * (n_par + 1))
    broyden = _Broyden(prob, BROYDEN_EVERY) if BROYDEN_EVERY > 1 else None
    updated = False
    try:
        if broyden is not None:
            sol = least_squares(prob.residuals, best_u, jac=broyden, bounds=(np.zeros(n_par), np.ones(n_par)),
                                method="trf", x_scale=1.0, max_nfev=budget, xtol=1e-3, ftol=1e-3, gtol=1e-6)
        else:
            ahead = {"workers": prob.ahead_map} if _LSQ_WORKERS else {}  # the Jacobian's columns side by side
            sol = least_squares(prob.residuals, best_u, bounds=(np.zeros(n_par), np.ones(n_par)), method="trf",
                                diff_step=0.02, x_scale=1.0, max_nfev=budget, xtol=1e-3, ftol=1e-3, gtol=1e-6,
                                **ahead)
        u, jac, message = np.asarray(sol.x, dtype=np.float64), sol.jac, str(sol.message)
        if broyden is not None and not broyden.fresh:
            jac = None  # a rank-one update is no Jacobian to read intervals from: a full one at the solution below
            updated = True
    except _Spent:
        assert prob.best is not None
        u, jac, message = prob.best[1], None, f"stopped after {prob.nfev} simulator passes (the pass budget)"
    prob.max_passes = None
    r = prob.residuals(u)
    offset = prob.last_offset  # of the solution itself (a Jacobian's passes move it)
    if jac is None and (effects or updated):
        jac = prob.jacobian(u, r)
    nui, settings = prob.decode(u, offset)
    values = {eff.id: dict(vals) for eff, vals in settings}
    at_bound = []
    lo_off, hi_off = bounds.offset_s
    if min(nui.offset_s - lo_off, hi_off - nui.offset_s) <= 0.01 * (hi_off - lo_off):
        at_bound.append("nuisance.offset_s")
    for spec, owner, ui in zip(prob.specs, prob.owner, u, strict=True):
        near = ui < 0.01 or ui > 0.99
        value = spec.lo + ui * (spec.hi - spec.lo)
        resting_off = owner != "nuisance" and abs(spec.off - value) <= 0.01 * (spec.hi - spec.lo)
        if near and not resting_off:
            at_bound.append(f"{owner}.{spec.name}")
    pairs = trade_offs(jac, [p.name for p in prob.specs], prob.owner) if effects and jac is not None else ()
    result = FitResult(tuple(e.id for e in effects), nui, values, _chi2(r), prob.n_res, prob.nfev, tuple(at_bound),
                       message, pairs, settings, r, None if jac is None else np.asarray(jac, dtype=np.float64))
    if memory is not None and key is not None:
        memory.current[key] = result
    return result


def chi2_at(base: Vehicle, events: Sequence[DiagEvent], split: Split, effects: Sequence[Effect],
            points: Sequence[FitResult], *, bounds: Bounds, model: str = "multibody") -> list[float]:
    """The calibration chi2 at each of ``points`` (their nuisance and values for every effect of ``effects``), one
    simulator pass each and no refinement: a screen of start points before a refinement is paid for."""
    require_calibration(split, events)
    prob = _Problem(base, events, effects, bounds, model)
    us = [prob.encode(p.nuisance, p.values) for p in points]
    prob.run_ahead(us)
    return [_chi2(prob.residuals(u)) for u in us]


def residual_moved(base: Vehicle, events: Sequence[DiagEvent], fitted: FitResult, effects: Sequence[Effect], *,
                   bounds: Bounds, model: str = "multibody") -> FloatArray | None:
    """The weighted calibration residual of ``fitted`` (its nuisance and ``effects``' values) evaluated on another
    vehicle ``base``, with the time offset profiled as in :func:`fit` (one simulator pass; None where the simulator
    rejects it): a column of the fit's sensitivity to something it held fixed."""
    prob = _Problem(base, events, effects, bounds, model)
    got = prob._evaluate(prob.encode(fitted.nuisance, fitted.values))
    return None if got is None else got[0]


def linear_cost(r0: FloatArray, cols: FloatArray, lo: FloatArray, hi: FloatArray) -> tuple[float, FloatArray]:
    """Least ``|r0 + cols a|^2`` over ``lo <= a <= hi``, and its ``a`` (a first-order step: :func:`linear_reach`,
    and the partner screen of :mod:`~app.analysis.diagnosis.partners`)."""
    if cols.shape[1] == 0:
        return float(r0 @ r0), np.zeros(0)
    sol = lsq_linear(cols, -r0, bounds=(lo, hi), method="bvls")
    a = np.asarray(sol.x, dtype=np.float64)
    res = r0 + cols @ a
    return float(res @ res), a


@dataclass(frozen=True)
class Reach:
    """What a refinement from a point can reach to first order (:func:`linear_reach`).

    Attributes
    ----------
    chi2 : calibration chi2 at the bounded Gauss-Newton step from the point (noise units).
    chi2_at : calibration chi2 at the point itself.
    n : residual samples.
    nfev : simulator passes it took (the point and one per parameter).
    """

    chi2: float
    chi2_at: float
    n: int
    nfev: int


@single_blas_thread()
def linear_reach(base: Vehicle, events: Sequence[DiagEvent], split: Split, effects: Sequence[Effect],
                 start: FitResult, *, bounds: Bounds, model: str = "multibody") -> Reach | None:
    """The calibration chi2 a refinement of ``effects`` (with the nuisance) from ``start`` reaches to first order.

    One pass at the start and one per unit-box parameter give the residual and its forward-difference Jacobian (the
    steps and the profiled time offset of :func:`fit`'s own refinement); the bounded linear least-squares step in the
    unit box is Gauss-Newton's first step without a trust region. Where the residual is near linear in the parameters
    the refinement ends near this promise; where it is not, it can end far below it (a progressive shaft's joint fit
    with the base: 37x, docs/diagnosis.md), so a caller weighs it with a margin measured for its own parameters. The
    promise costs ``1 + parameters`` passes against ``PASSES_PER_PARAM`` x that for the refinement. None when the
    simulator rejects the start.
    """
    require_calibration(split, events)
    prob = _Problem(base, events, effects, bounds, model)
    u0 = prob.encode(start.nuisance, start.values)
    r0 = prob.residuals(u0)
    if np.all(r0 == _PENALTY):
        return None
    promised, _ = linear_cost(r0, prob.jacobian(u0, r0), -u0, 1.0 - u0)
    return Reach(promised, _chi2(r0), prob.n_res, prob.nfev)
