"""Many parameter variants of one vehicle in one compiled loop; Monte Carlo tolerance analysis."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from sim.budget import MAX_BATCH_STEPS, MAX_STEPS, check_output, check_steps
from sim.errors import InstabilityError, ParameterError
from sim.inputs import prepare_input
from sim.integrate import STATUS_OK, is_kernel_layout, run_chain_batch
from sim.metrics import peak_to_valley, unloaded_time
from sim.model import ChainModel, deflections, quasi_static_full
from sim.params import Vehicle
from sim.simulate import RPM, _grid, _pair_events, airgap_input, choose_step, initial_speed

F64 = NDArray[np.float64]
EVENTS_PER_VARIANT = 2000


@dataclass(frozen=True)
class BatchResult:
    """Resolver speed of every variant on one grid.

    Attributes
    ----------
    t : (n,) s
    motor_speed_rpm : (n_variants, n) rpm, rotor relative to housing
    variants : the dotted-field changes of each variant
    gap_events : per variant, (gap, t_open, t_close) as in SimResult
    vehicle_speed_kmh : (n_variants, n) km/h, the vehicle body's speed (only with ``body_speed=True``)
    """

    t: F64
    motor_speed_rpm: F64
    variants: tuple[Mapping[str, Any], ...]
    gap_events: tuple[list[tuple[str, float, float]], ...]
    vehicle_speed_kmh: F64 | None = None


def simulate_batch(
    vehicle: Vehicle, variants: Sequence[Mapping[str, Any]], t_s: ArrayLike, torque_nm: ArrayLike, *,
    speed0_rpm: float | None = None, interp: Literal["hold", "linear"] = "hold", output_dt: float = 0.001,
    body_speed: bool = False,
) -> BatchResult:
    """Simulate ``vehicle.with_changes(v)`` for every ``v`` in ``variants`` (multibody model).

    ``body_speed`` also returns every variant's vehicle speed (what the occupants' acceleration is the
    derivative of).

    Variants may change any numeric field but not the topology (half-shaft segments, housing
    on/off). Each variant gets its own stable step. The vehicle's torque gain applies to all. Effects
    other than rotor drag and torque lag are not applied (the batch returns resolver speed only).

    Raises
    ------
    ParameterError : an invalid change, or a variant that changes the topology
    InstabilityError : a variant diverged (its index is named)
    """
    return _simulate_batch(vehicle, variants, lambda k: vehicle.with_changes(variants[k]).compiled,
                           t_s, torque_nm, speed0_rpm=speed0_rpm, interp=interp, output_dt=output_dt,
                           body_speed=body_speed)


def _simulate_batch(
    vehicle: Vehicle, variants: Sequence[Mapping[str, Any]], chain_of: Callable[[int], ChainModel], t_s: ArrayLike,
    torque_nm: ArrayLike, *, speed0_rpm: float | None, interp: Literal["hold", "linear"], output_dt: float,
    body_speed: bool,
) -> BatchResult:
    """:func:`simulate_batch` with the compiled chain of variant ``k`` from ``chain_of(k)``, asked in order."""
    inp = prepare_input(t_s, torque_nm, interp)
    if not variants:
        raise ParameterError("variants", list(variants), "need at least one variant")
    if any("motor.torque_gain" in v for v in variants):
        raise ParameterError("variants", [dict(v) for v in variants], "the torque gain is the vehicle's, one for all "
                             "variants: scale the torque instead")
    inp = airgap_input(vehicle, inp)  # the logged torque as the air-gap torque, as sim.simulate
    chains = []
    for k in range(len(variants)):
        try:
            chains.append(chain_of(k))
        except ParameterError as exc:
            raise ParameterError(f"variants[{k}].{exc.field}", exc.value, exc.reason) from exc
    ref = chains[0]
    if not is_kernel_layout(ref.ca, ref.cb, ref.housing):
        raise ValueError("the kernel needs the layout of sim.model.build_chain (mount last)")
    for k, c in enumerate(chains):
        if c.body_names != ref.body_names:
            raise ParameterError(f"variants[{k}]", variants[k], "changes the model topology; batch needs one topology")
    t0, n_out = _grid(inp, output_dt)
    span = float(inp.t[-1]) - t0
    nv = len(chains)
    check_output(span, output_dt, n_out, (32 if body_speed else 16) * nv)  # kernel buffers and the copies
    w0 = initial_speed(vehicle, speed0_rpm)
    states = [quasi_static_full(c, float(inp.torque[0]), w0) for c in chains]
    q_max = float(np.max(np.abs(inp.torque)))
    steps = [choose_step(c, output_dt, torque_max=q_max,
                         omega_vehicle=float(s[1][c.vehicle]) if c.vehicle >= 0 else 0.0)
             for c, s in zip(chains, states, strict=True)]
    for k, (step, sub) in enumerate(steps):
        check_steps(span, step, (n_out - 1) * sub, auto=True, what=f"variant {k}")
    total = sum((n_out - 1) * sub for _, sub in steps)
    check_steps(span, min(s[0] for s in steps), total, auto=True, limit=MAX_BATCH_STEPS,
                what=f"all {nv} variants together")

    def stack(name: str) -> F64:
        return np.ascontiguousarray(np.stack([getattr(c, name) for c in chains]))

    out = np.zeros((nv, n_out))
    ev_gap = np.zeros((nv, EVENTS_PER_VARIANT), dtype=np.int64)
    ev_t = np.zeros((nv, EVENTS_PER_VARIANT))
    ev_kind = np.zeros((nv, EVENTS_PER_VARIANT), dtype=np.int64)
    status = np.zeros(nv, dtype=np.int64)
    n_events = np.zeros(nv, dtype=np.int64)
    out_body = np.zeros((nv if body_speed else 0, n_out))
    body = ref.vehicle if ref.vehicle >= 0 else ref.wheel
    eff = vehicle.effects
    run_chain_batch(
        stack("inertia"), ref.ca, ref.cb, ref.cr, ref.ce, stack("ck"), stack("ck3"), stack("cc"), stack("chalf"),
        stack("cramp"), ref.cb2, ref.rotor, ref.housing, ref.wheel, ref.wheel2, stack("wheel_drag"), stack("road"),
        stack("rotor_drag"),
        np.array([eff.torque_lag.delay_s, eff.torque_lag.tau_s]), eff.speed_sensor.tau_s,
        ref.vehicle, np.stack([[c.tyre[0], c.tyre[1], s[2]] for c, s in zip(chains, states, strict=True)]),
        inp.t, inp.torque, inp.linear, t0, np.array([s[0] for s in steps]), n_out,
        np.array([s[1] for s in steps], dtype=np.int64),
        np.stack([s[0] for s in states]), np.stack([s[1] for s in states]), 20.0 * abs(w0) + 5000.0,
        out, ev_gap, ev_t, ev_kind, status, n_events, out_body, body,
    )
    bad = np.flatnonzero(status != STATUS_OK)
    if bad.size:
        raise InstabilityError(f"variant {int(bad[0])} ({dict(variants[int(bad[0])])}) diverged")
    events = []
    for v in range(nv):
        gap_of = {j: g for g, j in chains[v].gap_coupling.items()}
        raw = [(gap_of[int(ev_gap[v, k])], float(ev_t[v, k]), int(ev_kind[v, k]))
               for k in range(int(n_events[v])) if int(ev_gap[v, k]) in gap_of]
        delta = deflections(chains[v], states[v][0])
        open0 = {g: bool(abs(delta[j]) < chains[v].chalf[j]) for g, j in chains[v].gap_coupling.items()}
        events.append(_pair_events(raw, open0, t0))
    t = np.asarray(t0 + np.arange(n_out) * output_dt, dtype=np.float64)
    radius = np.array([c.road[0] for c in chains])[:, None]  # m, per variant
    return BatchResult(t=t, motor_speed_rpm=out * RPM, variants=tuple(variants), gap_events=tuple(events),
                       vehicle_speed_kmh=out_body * radius * 3.6 if body_speed else None)


@dataclass(frozen=True)
class ToleranceResult:
    """Distribution of ripple over the tolerance bands.

    Attributes
    ----------
    fluct_rpm : (n,) peak-to-adjacent-valley of the resolver speed in the window, per variant
    unloaded_ms : (n,) first unloaded interval after the window start, per variant
    samples : (n, p) sampled values, columns named by ``fields``
    t, vehicle_speed_kmh : (m,) s and (n + 1, m) km/h, the nominal's (row 0) and every variant's vehicle
        speed, only with ``body_speed=True`` (for the acceleration the occupants feel)
    """

    fluct_rpm: F64
    unloaded_ms: F64
    samples: F64
    fields: tuple[str, ...]
    nominal_fluct_rpm: float
    t: F64 | None = None
    vehicle_speed_kmh: F64 | None = None

    def band(self, lo: float = 5.0, hi: float = 95.0) -> tuple[float, float]:
        """Percentile band (rpm) of the predicted fluctuation."""
        return float(np.percentile(self.fluct_rpm, lo)), float(np.percentile(self.fluct_rpm, hi))

    def percentile_of(self, measured_rpm: float) -> float:
        """Where a measured fluctuation falls in the predicted distribution (0-100)."""
        return float(100.0 * np.mean(self.fluct_rpm <= measured_rpm))


ProgressFn = Callable[[int, int], None]
TOLERANCE_CHUNK = 100  # variants per compiled batch: progress granularity and bounded buffers


@dataclass(frozen=True)
class ToleranceSample:
    """The ``n`` variants of a vehicle drawn over its tolerance bands (:func:`tolerance_sample`).

    Each variant is built (changed, validated, its chain compiled) when first simulated and its compiled chain
    kept here, so the windows of one log that share a sample (:func:`tolerance_analysis` with ``sample``) build
    every variant once, not once per window.

    Attributes
    ----------
    vehicle : the nominal vehicle; n, seed, distribution : as drawn
    fields : the dotted fields sampled; samples : (n, p) their values; changes : per variant, field -> value
    """

    vehicle: Vehicle
    n: int
    seed: int
    distribution: str
    fields: tuple[str, ...]
    samples: F64
    changes: tuple[dict[str, float], ...]
    _chains: dict[int, ChainModel] = field(default_factory=dict, repr=False, compare=False)

    def chain(self, k: int) -> ChainModel:
        """The compiled chain of variant ``k`` (ParameterError when its changes do not make a valid vehicle)."""
        built = self._chains.get(k)
        if built is None:
            built = self._chains[k] = self.vehicle.with_changes(self.changes[k]).compiled
        return built


def tolerance_sample(vehicle: Vehicle, n: int = 1000, seed: int = 0,
                     distribution: Literal["uniform", "normal"] = "uniform") -> ToleranceSample:
    """Draw ``n`` variants over every gap's [min, max] band and every ``vehicle.tolerances`` band.

    ``uniform`` samples each band uniformly (a production spread with no better knowledge); ``normal`` takes
    the band as +-3 sigma about its midpoint, clipped to the band. The same ``seed`` gives the same variants.

    Raises
    ------
    ParameterError : invalid ``n``/``distribution``
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ParameterError("n", n, "must be an integer >= 1")
    if distribution not in ("uniform", "normal"):
        raise ParameterError("distribution", distribution, "must be 'uniform' or 'normal'")
    rng = np.random.default_rng(seed)
    bands: dict[str, tuple[float, float]] = {f"gaps.{g}": (vehicle.gap(g).min, vehicle.gap(g).max)
                                             for g in vehicle.gap_names}
    bands.update(vehicle.tolerances)
    fields = tuple(bands)
    lo = np.array([bands[f][0] for f in fields])
    hi = np.array([bands[f][1] for f in fields])
    if distribution == "uniform":
        x = rng.uniform(lo, hi, size=(n, len(fields)))
    else:
        x = np.clip(rng.normal((lo + hi) / 2, (hi - lo) / 6, size=(n, len(fields))), lo, hi)
    changes = tuple(dict(zip(fields, (float(v) for v in row), strict=True)) for row in x)
    x.flags.writeable = False  # shared by every result drawn from this sample
    return ToleranceSample(vehicle, n, seed, distribution, fields, x, changes)


def tolerance_analysis(
    vehicle: Vehicle, t_s: ArrayLike, torque_nm: ArrayLike, *, n: int = 1000, seed: int = 0,
    window: tuple[float, float] | None = None, distribution: Literal["uniform", "normal"] = "uniform",
    speed0_rpm: float | None = None, interp: Literal["hold", "linear"] = "hold", output_dt: float = 0.001,
    progress: ProgressFn | None = None, body_speed: bool = False, sample: ToleranceSample | None = None,
) -> ToleranceResult:
    """Monte Carlo over every gap's [min, max] band and every ``vehicle.tolerances`` band.

    ``uniform`` samples each band uniformly (a production spread with no better knowledge);
    ``normal`` takes the band as +-3 sigma about its midpoint, clipped to the band. The
    window (s) bounds the fluctuation metric; default: the whole input. Variants run in
    compiled batches of ``TOLERANCE_CHUNK``; ``progress(done, n)`` is called after each (and
    once with ``done = 0`` before the first). The same ``seed`` gives the same result.
    ``body_speed`` keeps every run's vehicle speed (``t``, ``vehicle_speed_kmh``).
    ``sample``: variants of ``vehicle`` drawn before (:func:`tolerance_sample`), shared by several inputs (the
    windows of one log) so each variant is built once; ``n``, ``seed`` and ``distribution`` are then the
    sample's. Without it the variants are drawn here (the same ones, for the same arguments).

    Raises
    ------
    ParameterError : invalid ``n``/``distribution``, or the whole analysis would take more than
        ``sim.budget.MAX_BATCH_STEPS`` integrator steps (field ``dt``, with the numbers)
    InputSignalError, InstabilityError : as :func:`simulate_batch`
    """
    if sample is None:
        sample = tolerance_sample(vehicle, n, seed, distribution)
    elif sample.vehicle is not vehicle:
        raise ValueError("the tolerance sample was drawn for another vehicle object")
    n, variants = sample.n, sample.changes
    _check_analysis_budget(vehicle, t_s, torque_nm, n + 1, speed0_rpm, interp, output_dt)
    report = progress if progress is not None else (lambda done, total: None)
    report(0, n)
    runs: list[BatchResult] = []
    for start in range(0, n, TOLERANCE_CHUNK):
        chunk = variants[start:start + TOLERANCE_CHUNK]
        first = 1 if start == 0 else 0  # the nominal leads the first batch

        def chain_of(k: int, start: int = start, first: int = first) -> ChainModel:
            return vehicle.compiled if k < first else sample.chain(start + k - first)

        runs.append(_simulate_batch(vehicle, [{}, *chunk] if first else chunk, chain_of, t_s, torque_nm,
                                    speed0_rpm=speed0_rpm, interp=interp, output_dt=output_dt,
                                    body_speed=body_speed))
        report(start + len(chunk), n)
    t = runs[0].t
    speeds = np.concatenate([r.motor_speed_rpm for r in runs])
    events = [ev for r in runs for ev in r.gap_events]
    w0, w1 = window if window is not None else (float(t[0]), float(t[-1]))
    fl = np.array([peak_to_valley(t, s, w0, w1) for s in speeds])
    ul = np.array([unloaded_time(ev, w0, w1) for ev in events]) * 1e3
    body = (np.concatenate([r.vehicle_speed_kmh for r in runs if r.vehicle_speed_kmh is not None])
            if body_speed else None)
    return ToleranceResult(fluct_rpm=fl[1:], unloaded_ms=ul[1:], samples=sample.samples, fields=sample.fields,
                           nominal_fluct_rpm=float(fl[0]), t=t if body_speed else None, vehicle_speed_kmh=body)


def _check_analysis_budget(vehicle: Vehicle, t_s: ArrayLike, torque_nm: ArrayLike, runs: int,
                           speed0_rpm: float | None, interp: str, output_dt: float) -> None:
    """Refuse up front an analysis whose ``runs`` runs at the nominal step exceed ``MAX_BATCH_STEPS``."""
    inp = prepare_input(t_s, torque_nm, interp)
    t0, n_out = _grid(inp, output_dt)
    check_output(float(inp.t[-1]) - t0, output_dt, n_out, 32 * runs)  # every variant's speeds, kept for metrics
    chain = vehicle.compiled
    _, omega0, _ = quasi_static_full(chain, float(inp.torque[0]), initial_speed(vehicle, speed0_rpm))
    step, sub = choose_step(chain, output_dt, torque_max=float(np.max(np.abs(inp.torque))),
                            omega_vehicle=float(omega0[chain.vehicle]) if chain.vehicle >= 0 else 0.0)
    span = float(inp.t[-1]) - t0
    check_steps(span, step, (n_out - 1) * sub, auto=True, limit=MAX_STEPS, what="one variant")
    check_steps(span, step, runs * (n_out - 1) * sub, auto=True, limit=MAX_BATCH_STEPS,
                what=f"{runs} variants at the nominal step")


__all__ = ["BatchResult", "ToleranceResult", "ToleranceSample", "simulate_batch", "tolerance_analysis",
           "tolerance_sample"]
