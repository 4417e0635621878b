"""The one place that chains the stages: log -> signals -> events -> simulation -> alignment -> metrics.

::

    run_analysis(log, VehicleInputs, AnalysisOptions, progress)
      decode     open_log + load_database + load_signal_map + load_signals  -> SignalSet
      check      time base, torque sign, plausibility, computed road speeds -> [Finding]
      events     detect_events                                              -> [Event]
      simulate   sim.simulate per included event window (from the measured speed at its start),
                 and once over the whole log
      align      common time base; torque-to-speed offset = lag of measured behind simulated speed
      metrics    ripple metrics of measured and (offset-corrected) simulated speed, differences

Progress goes to ``progress(fraction, stage)`` (:class:`app.progress.Progress`), ``fraction`` in 0..1 over
the whole run; nothing here prints. Results are plain dataclasses; :func:`app.pipeline_results.result_payload`
turns them into JSON + arrays for storage.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field, fields, is_dataclass, replace
from pathlib import Path
from typing import Any, Literal

import numpy as np

from app.analysis.accel import AccelSource, acceleration_source
from app.analysis.align import OffsetEstimate, common_time_base, estimate_lag, overlap, shift
from app.analysis.compare import EventComparison, SpeedError, compare_event, speed_error
from app.analysis.diagnosis.uncertainty import rigid_inertia
from app.analysis.drivability import DrivabilityParams
from app.analysis.events import SPEED, TORQUE, Event, EventParams, find_events
from app.analysis.feel import FeelComparison, event_feel, run_feel
from app.analysis.lash import LashParams
from app.analysis.logchecks import CheckParams, Finding, Limits, check_log
from app.analysis.metrics import MetricParams, ripple_metrics
from app.analysis.sampling import sample_period
from app.analysis.series import FloatArray, finite_signal
from app.analysis.slip import Drive, log_ratio_scale
from app.analysis.tolerance import EventWindow, check_request, tolerance_doc
from app.analysis.tracking import TrackingParams, Verdict, event_verdict, log_verdict
from app.errors import (
    InputError,
    InsufficientDataError,
    MissingSignalError,
    SignalMapError,
    WorkLimitError,
)
from app.ingest.database import load_database
from app.ingest.dbc_cache import cached_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.readers import open_log
from app.ingest.readreport import read_summary
from app.ingest.signalmap import load_signal_map
from app.log_source import LogSource, opened
from app.progress import Progress, no_progress, within
from app.serial import Serial
from app.signals import Signal, SignalSet
from app.vehicle_check import steps_per_second, trial_vehicle
from sim import SimError, SimResult, Vehicle, WhatIf, load_vehicle, simulate
from sim.layout import shaft_gap
from sim.metrics import unloaded_time
from sim.paper import run_case, sensitivities, sensitivity_unit

REQUIRED = (TORQUE, SPEED)
MAX_OPTION_S = 10.0  # a duration option beyond this is a mistake: windows and arrays are sized by it
RATE_SUFFIXES = ("_nm_s", "_rpm_s")  # fields ending in _s that are rates (min_rate_nm_s), not durations


@dataclass(frozen=True)
class AnalysisOptions(Serial):
    model: Literal["multibody", "two_inertia"] = "multibody"
    events: EventParams = field(default_factory=EventParams)
    metrics: MetricParams = field(default_factory=MetricParams)
    tracking: TrackingParams = field(default_factory=TrackingParams)
    checks: CheckParams = field(default_factory=CheckParams)
    fit_offset: bool = True
    max_offset_s: float = 0.05  # the torque-to-speed offset is searched within ± this
    event_dt_s: float = 0.001  # time base of the per-event aligned series
    whole_log: bool = True  # also simulate the whole log in one open-loop run
    torque_interp: Literal["hold", "linear"] = "linear"
    drivability: DrivabilityParams = field(default_factory=DrivabilityParams)  # acceleration criteria per event

    @classmethod
    def from_dict(cls, data: dict[str, Any] | None) -> AnalysisOptions:
        data = dict(data or {})
        ev_kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.pop("events", {}).items()}
        mp_kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in data.pop("metrics", {}).items()}
        tr_kw: dict[str, Any] = dict(data.pop("tracking", {}) or {})
        ck_kw: dict[str, Any] = dict(data.pop("checks", {}) or {})
        dr_kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v
                                 for k, v in (data.pop("drivability", {}) or {}).items()}
        try:
            if isinstance(mp_kw.get("lash"), dict):
                lash_kw: dict[str, Any] = {k: tuple(v) if isinstance(v, list) else v for k, v in mp_kw["lash"].items()}
                mp_kw["lash"] = LashParams(**lash_kw)
            opts = cls(events=EventParams(**ev_kw), metrics=MetricParams(**mp_kw), tracking=TrackingParams(**tr_kw),
                       checks=CheckParams(**ck_kw), drivability=DrivabilityParams(**dr_kw), **data)
        except (TypeError, ValueError) as exc:
            raise InputError(f"analysis options: {exc}") from exc
        if opts.model not in ("multibody", "two_inertia"):
            raise InputError(f"analysis options: model = {opts.model!r}; use 'multibody' or 'two_inertia'")
        if not 0 <= opts.max_offset_s <= 1.0 or not 1e-4 <= opts.event_dt_s <= 0.05:
            raise InputError("analysis options: max_offset_s must be in [0, 1] s and event_dt_s in [1e-4, 0.05] s")
        _check_ranges(opts, "")
        return opts


def _check_ranges(params: Any, prefix: str) -> None:
    """Every number of ``params`` (and of the parameter sets inside it) finite, every duration (a field
    ending in ``_s``, rates aside) within ±``MAX_OPTION_S``: otherwise :class:`InputError` naming the field."""
    for f in fields(params):
        value = getattr(params, f.name)
        if is_dataclass(value):
            _check_ranges(value, f"{prefix}{f.name}.")
            continue
        numbers = [v for v in (value if isinstance(value, tuple) else (value,))
                   if isinstance(v, int | float) and not isinstance(v, bool)]
        if any(not math.isfinite(v) for v in numbers):
            raise InputError(f"analysis options: {prefix}{f.name} = {value!r}: must be a finite number")
        if f.name.endswith("_s") and not f.name.endswith(RATE_SUFFIXES) and any(abs(v) > MAX_OPTION_S for v in numbers):
            raise InputError(f"analysis options: {prefix}{f.name} = {value!r}: durations are at most "
                             f"{MAX_OPTION_S:g} s")


@dataclass(frozen=True)
class VehicleInputs:
    """What an analysis needs about the vehicle: the driveline, its DBC and the signal map."""

    vehicle: Vehicle
    database: Path
    signal_map: Path
    name: str | None = None  # the registered vehicle's name, when it comes from the store (else the driveline's)


@dataclass(frozen=True)
class Aligned:
    """Measured and simulated speed (rpm) and torque (N m) on one uniform time base ``t`` (s), all (n,)."""

    t: FloatArray
    measured_rpm: FloatArray
    simulated_rpm: FloatArray
    torque_nm: FloatArray


@dataclass(frozen=True)
class EventResult:
    event: Event
    aligned: Aligned | None = None
    comparison: EventComparison | None = None
    sim_gap_open_time_s: float = float("nan")  # the simulator's own first-gap-open to last-gap-close time
    error: str | None = None  # why this included event has no metrics (simulation failed, too few samples)
    tracking: Verdict | None = None  # does the simulation follow the measured speed here (None: no metrics)
    feel: FeelComparison | None = None  # drivability criteria, measured and simulated (None: no acceleration)


@dataclass(frozen=True)
class AnalysisResult:
    signals: SignalSet
    events: list[Event]
    event_results: list[EventResult]
    offset: OffsetEstimate
    whole: Aligned | None
    whole_error: SpeedError | None
    ingest: dict[str, Any] = field(default_factory=dict)
    timings_s: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    tracking: Verdict = field(default_factory=lambda: Verdict("unknown", ["no analysed event to judge"]))
    findings: list[Finding] = field(default_factory=list)  # problems of the log as decoded (app.analysis.logchecks)
    acceleration: AccelSource | None = None  # where the drivability criteria's measured acceleration comes from


def decode_log(log: LogSource, database: Path, signal_map: Path,
               progress: Progress = no_progress) -> tuple[SignalSet, dict[str, Any]]:
    """Read and decode a log into canonical signals; returns the signals and an ingest summary.

    ``log`` is a path, a binary file object, or an fsspec URL (:mod:`app.log_source`). The DBC is
    parsed once per content per process (:mod:`app.ingest.dbc_cache`). ``ingest["start_time"]`` is
    the log's absolute start (ISO 8601) when the format records it, else None; ``ingest["read"]`` what
    reading lost (:func:`app.ingest.readreport.read_summary`: damaged, truncated, frames and seconds lost,
    a one-sentence ``note``).
    """
    loaded = cached_database(database)
    smap = load_signal_map(signal_map)
    with opened(log) as src, open_log(src) as reader:
        signals, report = load_signals(reader, loaded, smap, progress=within(progress, 0.0, 1.0, "decode"),
                                       require=REQUIRED)
        meta, read_report = reader.meta, reader.report
    ingest = {
        "format": meta.format, "frames": read_report.frames, "read_issues": len(read_report.issues),
        "database": loaded.name, "database_repairs": [asdict(r) for r in loaded.repairs],
        "decode": _plain(report), "channels": sorted(signals),
        "start_time": meta.start_time.isoformat() if meta.start_time else None, "start_clock": meta.start_clock,
        "read": read_summary(meta, read_report, read_report.frames, report.duration_s),
    }
    return signals, ingest


def _plain(obj: Any) -> Any:
    """A report object as JSON-friendly data (dataclass, mapping or its public attributes)."""
    if is_dataclass(obj) and not isinstance(obj, type):
        return asdict(obj)
    if isinstance(obj, dict):
        return obj
    return {k: v for k, v in vars(obj).items() if not k.startswith("_")} if hasattr(obj, "__dict__") else str(obj)


def check_vehicle_files(driveline: Path, database: Path, signal_map: Path) -> dict[str, Any]:
    """Load all three vehicle files and check that the signal map fits the database.

    The driveline must also pass a cheap simulation trial (:func:`app.vehicle_check.trial_vehicle`).
    Raises ParameterError (driveline), DatabaseError, SignalMapError; returns a summary.
    """
    vehicle = load_vehicle(driveline)
    steps = trial_vehicle(vehicle, driveline.name)
    loaded, routes = signal_routes(database, signal_map)
    missing = [c for c in REQUIRED if c not in routes]
    if missing:
        raise SignalMapError(f"signal map {signal_map.name} does not map {missing}, which every analysis needs")
    return {"vehicle": vehicle.name, "description": vehicle.description, "ratio": vehicle.ratio,
            "stages": [f"{s.name} ({s.kind})" for s in vehicle.chain], "housing": vehicle.housing.enabled,
            "steps_per_simulated_s": steps, "database": database.name, "database_repairs": len(loaded.repairs),
            "channels": {c: f"{m}.{s}" for c, (m, s) in sorted(routes.items())}}


def signal_routes(database: Path, signal_map: Path) -> tuple[Any, dict[str, tuple[str, str]]]:
    """The loaded database and, per canonical channel, the (message, signal) the map reads it from."""
    loaded = load_database(database)
    smap = load_signal_map(signal_map)
    routes = smap.routes(loaded.db)
    return loaded, dict(routes)


WHOLE_LOG_MAX_ROWS = 1_000_000  # ~330 MB of simulator output; per-event runs keep their fine grid


def whole_log_output_dt(span_s: float, speed_period_s: float) -> float:
    """Output step (s) of the whole-log run: the speed signal's own period (1-20 ms), coarser for
    very long logs so the open-loop comparison stays within ``WHOLE_LOG_MAX_ROWS`` samples."""
    return float(max(np.clip(speed_period_s, 1e-3, 0.02), span_s / WHOLE_LOG_MAX_ROWS))


def free_rotor_inertia(vehicle: Vehicle) -> float:
    """Motor-referred inertia (kg m^2) that moves with the rotor while the half-shaft gap is open.

    The rotor and every reducer body up to the half-shaft gap, each times its squared speed
    ratio to the rotor. With the reducer gaps open as well only the rotor moves freely; the
    gap-open estimate fits a rescaling of this inertia (``MetricParams.lash.inertia_range``).
    """
    chain = vehicle.compiled
    last = int(chain.ca[chain.gap_coupling[shaft_gap(vehicle)]])
    return float(sum(chain.inertia[b] * chain.speed_ratio[b] ** 2 for b in range(last + 1)))


def _simulate(vehicle: Vehicle, torque: Signal, speed: Signal, t0: float, t1: float,
              opts: AnalysisOptions, output_dt: float) -> SimResult:
    m = (torque.t >= t0) & (torque.t <= t1)
    tq_t, tq_v = torque.t[m], torque.values[m]
    if tq_t.size < 2:
        raise InsufficientDataError(f"torque has {tq_t.size} samples between {t0:.3f} and {t1:.3f} s")
    speed0 = float(speed.at([tq_t[0]])[0])
    return simulate(vehicle, tq_t, tq_v, model=opts.model, speed0_rpm=speed0 if np.isfinite(speed0) else None,
                    interp=opts.torque_interp, output_dt=output_dt)


def _sim_signal(res: SimResult) -> Signal:
    return Signal("simulated_speed_rpm", res.t, res.motor_speed_rpm, "rpm")


def _pooled_lag(pairs: list[tuple[FloatArray, FloatArray]], dt: float, max_lag_s: float) -> OffsetEstimate:
    """Lag of measured behind simulated speed over all events (NaN gaps keep events apart)."""
    if not pairs:
        return OffsetEstimate(0.0, float("nan"), 0)
    gap = np.full(int(max_lag_s / dt) + 2, np.nan)
    sim = np.concatenate([x for s, _ in pairs for x in (s, gap)])
    meas = np.concatenate([x for _, m in pairs for x in (m, gap)])
    return estimate_lag(sim, meas, dt, max_lag_s)


def analyze_signals(signals: SignalSet, vehicle: Vehicle, options: AnalysisOptions | None = None,
                    progress: Progress = no_progress, start: float = 0.0) -> AnalysisResult:
    """Events, simulation, alignment and metrics for decoded signals (see the module docstring)."""
    opts = options or AnalysisOptions()
    if opts.metrics.free_rotor_inertia_kgm2 is None:
        opts = replace(opts, metrics=replace(opts.metrics, free_rotor_inertia_kgm2=free_rotor_inertia(vehicle)))
    clock = time.perf_counter()
    timings: dict[str, float] = {}

    part = within(progress, start, 1.0 - start)

    def stage(name: str, frac: float) -> None:
        part(frac, name)

    for name in REQUIRED:
        if name not in signals:
            raise MissingSignalError(f"the analysis needs channel {name!r}; decoded channels: {sorted(signals)}")
    checks = check_log(signals, Limits.for_vehicle(vehicle), opts.checks)
    signals = checks.signals
    torque, speed = finite_signal(signals[TORQUE]), finite_signal(signals[SPEED])
    stage("events", 0.0)
    notes: list[str] = []
    mismatch: list[str] = []  # reasons the comparison is not valid, found before any simulation
    drive = Drive(vehicle.ratio, vehicle.wheel.radius, rigid_inertia(vehicle), computed=checks.computed)
    scale = log_ratio_scale(signals, drive, opts.events.slip_min_speed_rpm)
    if scale is not None and abs(scale - 1.0) > opts.events.max_wheel_slip:
        mismatch.append(f"the vehicle does not fit the log: the motor turns {scale:.2f}x the speed the file's ratio "
                        f"{vehicle.ratio:g} and tyre radius {vehicle.wheel.radius:g} m give from the road speed "
                        f"(lower quartile over the log); wheel slip is checked against the log's own ratio "
                        f"{vehicle.ratio * scale:.3g}")
        drive = replace(drive, ratio=vehicle.ratio * scale)
    accel: AccelSource | None = None
    feel_s = 0.0  # time spent on the drivability criteria; moved out of the stage timings by advancing `clock`
    if opts.drivability.enabled:
        clock_feel = time.perf_counter()
        try:
            accel = acceleration_source(signals, vehicle.wheel.radius, opts.drivability.derive_cutoff_hz,
                                        checks.computed)
            if accel is None:
                notes.append("no acceleration: the log has no accelerometer and no road speed; drivability "
                             "criteria are left out")
        except InsufficientDataError as exc:
            accel = None
            notes.append(f"no acceleration: {exc}; drivability criteria are left out")
        checks.findings.extend(accel.findings if accel is not None else [])
        feel_s = time.perf_counter() - clock_feel
        clock += feel_s
    detection = find_events(signals, opts.events, drive)
    events = detection.events
    timings["events"] = time.perf_counter() - clock
    included = [e for e in events if e.included]
    if detection.ringing:
        notes.append(f"{detection.ringing} torque changes rejected as ringing (a side shorter than "
                     f"{opts.events.min_dwell_s * 1e3:.0f} ms, or the torque not moving one way through the crossing)")

    # 1. simulate each event window, on a fine common time base
    sims: dict[int, tuple[SimResult, FloatArray]] = {}
    errors: dict[int, str] = {}
    dt = opts.event_dt_s
    for k, ev in enumerate(included):
        stage("simulate", 0.05 + 0.45 * k / max(1, len(included)))
        try:
            res = _simulate(vehicle, torque, speed, ev.t_start_s - opts.max_offset_s, ev.t_end_s, opts, dt)
        except (SimError, InsufficientDataError) as exc:
            errors[ev.index] = f"simulation failed: {exc}"
            continue
        sims[ev.index] = (res, common_time_base(ev.t_start_s, ev.t_end_s, dt))
    timings["simulate_events"] = time.perf_counter() - clock - sum(timings.values())

    # 2. the torque-to-speed offset, pooled over events
    stage("align", 0.5)
    offset = OffsetEstimate(0.0, float("nan"), 0)
    if opts.fit_offset and opts.max_offset_s > 0:
        pairs = [(_sim_signal(r).at(g), speed.at(g)) for r, g in sims.values()]
        offset = _pooled_lag(pairs, dt, opts.max_offset_s)
        if np.isfinite(offset.correlation) and offset.correlation < opts.tracking.min_offset_correlation:
            offset = replace(offset, applied=False)
            notes.append(f"torque-to-speed offset {offset.lag_s * 1e3:.1f} ms not applied: its correlation "
                         f"{offset.correlation:.2f} is below {opts.tracking.min_offset_correlation:g}")
        elif offset.samples and abs(offset.lag_s) >= 0.95 * opts.max_offset_s:
            notes.append(f"torque-to-speed offset {offset.lag_s * 1e3:.1f} ms is at the search bound "
                         f"±{opts.max_offset_s * 1e3:.0f} ms")
    lag = offset.lag_s if offset.applied else 0.0
    torque_shifted = shift(torque, lag)

    # 3. metrics per event, measured vs offset-corrected simulation
    results: list[EventResult] = []
    for ev in events:
        if not ev.included:
            results.append(EventResult(ev))
            continue
        if ev.index not in sims:
            results.append(EventResult(ev, error=errors.get(ev.index)))
            continue
        res, grid = sims[ev.index]
        sim_sig = shift(_sim_signal(res), lag)
        aligned = Aligned(grid, speed.at(grid), sim_sig.at(grid), torque.at(grid))
        w = speed.window(ev.t_start_s, ev.t_end_s)
        t_ref = ev.t_cross_s + lag
        try:
            m_meas = ripple_metrics(w.t, w.values, torque_shifted, t_ref, ev.direction, opts.metrics)
            m_sim = ripple_metrics(w.t, sim_sig.at(w.t), torque_shifted, t_ref, ev.direction, opts.metrics)
        except InsufficientDataError as exc:
            results.append(EventResult(ev, aligned, error=str(exc)))
            continue
        comparison = compare_event(ev.index, m_meas, m_sim, aligned.measured_rpm, aligned.simulated_rpm)
        gap_time = unloaded_time(res.gap_events, ev.t_cross_s - 0.2, ev.t_cross_s + 0.3)
        feel = None
        if accel is not None:
            clock_feel = time.perf_counter()
            try:
                feel = _event_feel(accel, res, lag, ev, signals, m_meas, m_sim, opts.drivability)
            except (InsufficientDataError, ValueError, np.linalg.LinAlgError) as exc:  # never fails the analysis
                notes.append(f"event {ev.index}: drivability criteria not computed ({exc})")
            spent = time.perf_counter() - clock_feel
            clock += spent
            feel_s += spent
        results.append(EventResult(ev, aligned, comparison, gap_time,
                                   tracking=event_verdict(comparison, opts.tracking), feel=feel))
    stage("metrics", 0.75)
    timings["align_metrics"] = time.perf_counter() - clock - sum(timings.values())

    # 4. the whole log in one open-loop run
    whole: Aligned | None = None
    whole_err: SpeedError | None = None
    if opts.whole_log:
        t0, t1 = overlap([torque, speed])
        dt_whole = whole_log_output_dt(t1 - t0, sample_period(speed.t))
        try:
            res = _simulate(vehicle, torque, speed, t0, t1, opts, dt_whole)
            grid = common_time_base(t0, t1, dt_whole)
            whole = Aligned(grid, speed.at(grid), shift(_sim_signal(res), lag).at(grid), torque.at(grid))
            whole_err = speed_error(whole.measured_rpm, whole.simulated_rpm)
        except (SimError, InsufficientDataError) as exc:
            notes.append(f"whole-log simulation failed: {exc}")
        timings["simulate_whole"] = time.perf_counter() - clock - sum(timings.values())
    verdict = log_verdict([r.tracking for r in results if r.tracking is not None], opts.tracking,
                          offset.correlation if np.isfinite(offset.correlation) else None,
                          (whole.t, whole.measured_rpm, whole.simulated_rpm) if whole is not None else None,
                          mismatch)
    if opts.drivability.enabled:
        timings["drivability"] = feel_s
    stage("done", 1.0)
    return AnalysisResult(signals, events, results, offset, whole, whole_err, timings_s=timings, notes=notes,
                          tracking=verdict, findings=checks.findings, acceleration=accel)


def _event_feel(accel: AccelSource, res: SimResult, lag: float, ev: Event, signals: SignalSet, m_meas: Any,
                m_sim: Any, params: DrivabilityParams) -> FeelComparison:
    """The event's drivability criteria (:mod:`app.analysis.feel`), the simulation shifted by ``lag``."""
    def closure(m: Any) -> float:
        return float(m.t_gap_close_s if np.isfinite(m.t_gap_close_s) else m.t_impact_s)

    return event_feel(accel, res.t + lag, res.vehicle_speed_kmh / 3.6, res.vehicle_accel_ms2, ev.t_start_s,
                      ev.t_end_s, ev.t_cross_s + lag, ev.direction, params, pedal=signals.get("pedal_pct"),
                      t_close_measured=closure(m_meas), t_close_simulated=closure(m_sim),
                      shuffle_hint_hz=float(m_meas.shuffle_freq_hz), sim_seat_ms2=res.seat_rail_accel_ms2)


def run_analysis(log_path: LogSource, vehicle: VehicleInputs, options: AnalysisOptions | None = None,
                 progress: Progress = no_progress) -> AnalysisResult:
    """Decode ``log_path`` (a path, file object or URL) with the vehicle's DBC and signal map, then
    :func:`analyze_signals`. No side effects: the caller stores the result and runs the event-store hook
    (:func:`app.fleet.hook.after_analysis`), as the ``analysis`` job kind and ``lashscope analyze`` do."""
    clock = time.perf_counter()
    signals, ingest = decode_log(log_path, vehicle.database, vehicle.signal_map,
                                 within(progress, 0.0, 0.4))
    decode_s = time.perf_counter() - clock
    result = analyze_signals(signals, vehicle.vehicle, options, progress, start=0.4)
    result = replace(result, ingest=ingest, timings_s={"decode": decode_s, **result.timings_s})
    return result


GAP_SENSITIVITY_FORMAT = 3  # 2: units stated, per-mm and per-rad values side by side; 3: acceleration criteria per case
# stage-steps (cases x integrator steps per simulated second x stages) a gap sensitivity may cost: ~10-25 ns
# each, so about 5 s of CPU; the paper preset needs 1e6, a 24-stage chain of soft stages 2e7
MAX_GAP_SENSITIVITY_WORK = 4e8


def gap_sensitivity_work(vehicle: Vehicle) -> float:
    """What :func:`gap_sensitivity` will cost, in stage-steps, from the vehicle alone (no simulation).

    Raises :class:`~app.errors.WorkLimitError` past :data:`MAX_GAP_SENSITIVITY_WORK`, before any work."""
    chain = vehicle.chain
    work = (2 + 2 * len(vehicle.gap_names)) * steps_per_second(vehicle) * len(chain)
    if work > MAX_GAP_SENSITIVITY_WORK:
        raise WorkLimitError(f"the gap sensitivity of {vehicle.name} would take {work:.3g} stage-steps "
                             f"({len(vehicle.gap_names)} gaps, {len(chain)} stages), more than the limit of "
                             f"{MAX_GAP_SENSITIVITY_WORK:g}: fewer or softer stages")
    return work


def gap_sensitivity(vehicle: Vehicle, progress: Progress = no_progress) -> dict[str, Any]:
    """Gap what-ifs for a vehicle under the paper's scripted tip-in (see :mod:`sim.paper`).

    For each of the five gaps: the speed fluctuation and impact-induced fluctuation with the
    gap removed and halved (and the body acceleration's shuffle peak-to-peak, kick, jerk and VDV,
    :func:`app.analysis.feel.run_feel`), and the sensitivity ``S_i`` = (impact fluctuation of the nominal
    minus that without gap i) / size of gap i, normalised to the half-shaft gap = 100, next to
    the nominal and the zero-gap (no backlash at all) responses.

    The size of a gap is its circumferential clearance in mm (the paper's definition) when the
    vehicle gives every gap's contact radius, else its angle in rad in its own shaft; the
    document says which (``sensitivity_unit``) and carries both where both exist:
    ``sensitivity_per_mm`` (None without radii) and ``sensitivity_per_rad`` per gap.
    ``sensitivity`` is the one in ``sensitivity_unit``.
    """
    gap_sensitivity_work(vehicle)  # past its limit: refused before any simulation
    names = vehicle.gap_names  # the classic five, or the stage chain's gaps

    cases = {"nominal": run_case(vehicle, "nominal"), "zero_gaps": run_case(vehicle, "zero_gaps",
                                                                              WhatIf(gap_scale={"all": 0.0}))}
    gaps: list[dict[str, Any]] = []
    for i, g in enumerate(names, start=1):
        progress(i / (len(names) + 1), "gap_sensitivity")
        removed = cases[f"no_gap{i}"] = run_case(vehicle, f"no_gap{i}", WhatIf(gap_scale={g: 0.0}))
        halved = run_case(vehicle, f"half_gap{i}", WhatIf(gap_scale={g: 0.5}))
        gap = vehicle.gap(g)
        gaps.append({"gap": g, "nominal_rad": gap.nominal, "radius_mm": gap.radius_mm or None,
                     "clearance_mm": gap.arc_mm(name=g) if gap.radius_mm > 0 else None,
                     "removed": _case(removed), "halved": _case(halved)})
    unit = sensitivity_unit(vehicle)
    per_rad = sensitivities(vehicle, cases, per="rad")
    per_mm = sensitivities(vehicle, cases, per="mm") if unit == "mm" else [None] * len(names)
    for row, s_mm, s_rad in zip(gaps, per_mm, per_rad, strict=True):
        row["sensitivity_per_mm"] = None if s_mm is None else float(s_mm)
        row["sensitivity_per_rad"] = float(s_rad)
        row["sensitivity"] = row["sensitivity_per_mm"] if unit == "mm" else row["sensitivity_per_rad"]
    size = ("circumferential clearance in mm (angle x contact radius)" if unit == "mm"
            else "gap angle in rad in its own shaft (the vehicle gives no contact radii)")
    return {"format": GAP_SENSITIVITY_FORMAT, "vehicle": vehicle.name,
            "scenario": "tip-in -50 -> +150 N m over 0.135 s (sim.paper)",
            "sensitivity_unit": unit,
            "sensitivity_definition": ("S_i = (impact-induced fluctuation, nominal - with gap i removed) / size of "
                                       f"gap i, normalised to {shaft_gap(vehicle)} = 100; sensitivity is per {unit}: "
                                       "size = "
                                       f"{size}"),
            "nominal": _case(cases["nominal"]), "zero_gaps": _case(cases["zero_gaps"]), "gaps": gaps}


def _case(c: Any) -> dict[str, float]:
    """One what-if case: the speed metrics and what the occupants feel (body acceleration criteria)."""
    res = c.result
    feel = run_feel(res.t, res.vehicle_accel_ms2, res.airgap_torque_nm)
    return {"unloaded_ms": c.unloaded_ms, "fluctuation_rpm": c.fluct_rpm, "impact_rpm": c.impact_rpm,
            "rise_rpm": c.rise_rpm, "shuffle_pp_ms2": feel.shuffle_pp_ms2, "kick_ms2": feel.kick_ms2,
            "max_jerk_ms3": feel.max_jerk_ms3, "vdv_ms175": feel.vdv_ms175}


def tolerance_for_result(files: Any, vehicle: Vehicle, n: int, seed: int,
                         progress: Progress = no_progress, lead_s: float = 0.05) -> dict[str, Any]:
    """The tolerance band of every analysed event of a stored result (:mod:`app.analysis.tolerance`).

    ``files`` is a :class:`app.storage.results.ResultFiles` (or anything with ``doc`` and
    ``array``); the decoded torque and speed stored with the result drive the Monte Carlo,
    each event simulated from ``lead_s`` before its window (the analysis' offset search span).
    """
    check_request(n, seed)
    doc = files.doc
    sigs: dict[str, Signal] = {}
    for name in REQUIRED:
        meta = doc["signals"].get(name)
        if meta is None:
            raise MissingSignalError(f"the stored result has no {name!r} channel")
        k = meta["key"]
        sigs[name] = finite_signal(Signal(name, np.asarray(files.array(f"sig_{k}_t")),
                                          np.asarray(files.array(f"sig_{k}_v")), meta["unit"]))
    windows = [EventWindow(e["index"], e["kind"], e["t_start_s"] - lead_s, e["t_start_s"], e["t_end_s"],
                           e["t_cross_s"]) for e in doc["events"] if e["has_metrics"]]
    out = tolerance_doc(vehicle, sigs[TORQUE], sigs[SPEED], windows, n, seed, progress)
    by_index = {m["event_index"]: m for m in doc["metrics"]}
    for row in out["events"]:
        meas = by_index.get(row["index"], {}).get("measured") or {}
        row["analysis_fluctuation_rpm"] = meas.get("fluctuation_rpm")  # the detrended metric, for reference
        felt = ((by_index.get(row["index"], {}).get("drivability") or {}).get("measured") or {})
        pp = felt.get("shuffle_pp_ms2")
        row["measured_shuffle_pp_ms2"] = pp
        band = row.get("band_shuffle_pp_ms2")
        if pp is not None and np.isfinite(pp) and band is not None:
            row["measured_shuffle_pp_in_band"] = bool(band["p5"] <= pp <= band["p95"])
    return out
