"""Response and request bodies (published in the OpenAPI document)."""

from __future__ import annotations

import typing
from dataclasses import fields as dc_fields
from datetime import UTC, datetime
from typing import Any

from pydantic import BaseModel, ConfigDict, Field, create_model

from app.analysis.events import Event
from app.analysis.metrics import METRIC_NAMES, RippleMetrics
from app.api.tables import EVENT_COLUMNS
from app.progress import eta_seconds
from app.storage.records import AnalysisRecord, JobRecord, JobStatus, LogRecord, VehicleRecord


class ErrorOut(BaseModel):
    detail: str
    code: str


ERRORS: dict[int | str, dict[str, Any]] = {s: {"model": ErrorOut} for s in (400, 404, 409, 413, 415, 422, 500)}


class LogOut(BaseModel):
    id: str
    sha256: str
    filename: str
    size_bytes: int
    format: str
    status: str = "ready"
    created_at: str
    frames: int
    duration_s: float
    start_time: str | None
    issues: list[dict[str, Any]]
    duplicate: bool = False

    @classmethod
    def of(cls, r: LogRecord, duplicate: bool = False) -> LogOut:
        return cls(id=r.id, sha256=r.sha256, filename=r.filename, size_bytes=r.size_bytes, format=r.format,
                   created_at=r.created_at, frames=r.frames, duration_s=r.duration_s, start_time=r.start_time,
                   issues=r.issues, duplicate=duplicate)


LIST_DESCRIPTION_CHARS = 200


class VehicleOut(BaseModel):
    name: str
    version: int
    created_at: str
    sha256: str
    summary: dict[str, Any]
    files: dict[str, str]
    unchanged: bool = False

    @classmethod
    def of(cls, r: VehicleRecord, unchanged: bool = False, brief: bool = False) -> VehicleOut:
        """``brief`` (the listings): the description is cut to ``LIST_DESCRIPTION_CHARS``; one vehicle's
        own answer carries it whole."""
        summary = r.summary
        text = summary.get("description")
        if brief and isinstance(text, str) and len(text) > LIST_DESCRIPTION_CHARS:
            summary = {**summary, "description": text[:LIST_DESCRIPTION_CHARS] + "..."}
        return cls(name=r.name, version=r.version, created_at=r.created_at, sha256=r.sha256, summary=summary,
                   files={"driveline": r.driveline_path.name, "database": r.database_path.name,
                          "signal_map": r.signal_map_path.name}, unchanged=unchanged)


def job_timing(j: JobRecord, now: datetime | None = None) -> dict[str, float | None]:
    """``elapsed_s`` since a running job started and ``eta_s``, the seconds left at its pace so far
    (:func:`app.progress.eta_seconds`); both None unless the job is running (``eta_s`` also early on)."""
    if j.status is not JobStatus.RUNNING or not j.started_at:
        return {"elapsed_s": None, "eta_s": None}
    try:
        started = datetime.fromisoformat(j.started_at)
    except ValueError:
        return {"elapsed_s": None, "eta_s": None}
    if started.tzinfo is None:
        started = started.replace(tzinfo=UTC)
    elapsed = max(((now or datetime.now(UTC)) - started).total_seconds(), 0.0)
    eta = eta_seconds(j.progress, elapsed)
    return {"elapsed_s": round(elapsed, 1), "eta_s": None if eta is None else round(eta, 1)}


class JobOut(BaseModel):
    id: str
    status: str
    progress: float
    stage: str
    attempts: int
    created_at: str
    started_at: str | None
    finished_at: str | None
    error: ErrorOut | None
    elapsed_s: float | None = Field(None, description="seconds since a running job started")
    eta_s: float | None = Field(None, description="seconds a running job has left at its pace so far (a guide; "
                                "None early on)")

    @classmethod
    def of(cls, j: JobRecord) -> JobOut:
        err = ErrorOut(detail=j.error_detail or "", code=j.error_code) if j.error_code else None
        return cls(id=j.id, status=j.status.value, progress=j.progress, stage=j.stage, attempts=j.attempts,
                   created_at=j.created_at, started_at=j.started_at, finished_at=j.finished_at, error=err,
                   **job_timing(j))


class AnalysisCreate(BaseModel):
    log_id: str
    vehicle: str
    vehicle_version: int | None = None
    options: dict[str, Any] = Field(default_factory=dict, description="AnalysisOptions fields (app.pipeline)")


class AnalysisOut(BaseModel):
    id: str
    log_id: str
    vehicle: str
    vehicle_version: int
    options: dict[str, Any]
    created_at: str
    status: str
    progress: float
    job: JobOut
    summary: dict[str, Any]
    links: dict[str, str]

    @classmethod
    def of(cls, a: AnalysisRecord) -> AnalysisOut:
        base = f"/analyses/{a.id}"
        links = {"self": base, "events": f"{base}/events", "metrics": f"{base}/metrics", "speed": f"{base}/speed",
                 "signals": f"{base}/signals", "log": f"/logs/{a.log_id}",
                 "vehicle": f"/vehicles/{a.vehicle_name}/versions/{a.vehicle_version}"}
        return cls(id=a.id, log_id=a.log_id, vehicle=a.vehicle_name, vehicle_version=a.vehicle_version,
                   options=a.options, created_at=a.created_at, status=a.job.status.value, progress=a.job.progress,
                   job=JobOut.of(a.job), summary=a.summary, links=links)


class HealthOut(BaseModel):
    status: str
    version: str
    data_dir: str
    database: str
    jobs: dict[str, int]


class SeriesOut(BaseModel):
    """Aligned series: ``t_s`` and one list per column, all the same length (null where undefined)."""

    analysis_id: str
    event: int | None
    points: int
    source_points: int
    columns: list[str]
    t_s: list[float]
    measured_rpm: list[float | None] | None = None
    simulated_rpm: list[float | None] | None = None
    torque_nm: list[float | None] | None = None


class _Open(BaseModel):
    """A documented shape whose nested parts are described in the docs; unknown keys pass through."""

    model_config = ConfigDict(extra="allow")


# --- scientific payloads, typed (a generated client gets fields, not dicts) --------------------------------
# The per-event metric and event models are built from the column registries (app.analysis.metrics
# METRIC_NAMES and RippleMetrics, app.api.tables EVENT_COLUMNS, app.analysis.events.Event), so a column
# added there is a typed field here without editing this file; every model also passes unknown keys through.

UNIT_SUFFIXES = (("_rpm", "rpm"), ("_hz", "Hz"), ("_kgm2", "kg m^2"), ("_mps2", "m/s^2"), ("_mps3", "m/s^3"),
                 ("_ms2", "m/s^2"), ("_kmh", "km/h"), ("_nm_s", "N m/s"), ("_nm", "N m"), ("_pct", "%"),
                 ("_deg", "deg"), ("_ms", "ms"), ("_s", "s"), ("_g", "g"))


def unit_of(name: str) -> str:
    """The unit a column's name ends in (SI as the API sends it); ``-`` for ratios and counts."""
    return next((u for suffix, u in UNIT_SUFFIXES if name.endswith(suffix)), "-")


def _float_field(name: str, what: str) -> Any:
    unit = unit_of(name)
    return (float | None, Field(default=None, description=f"{what} ({unit})", json_schema_extra={"unit": unit}))


def _metric_values_model() -> type[BaseModel]:
    names = list(METRIC_NAMES) + [f.name for f in dc_fields(RippleMetrics)
                                  if f.name not in METRIC_NAMES and f.name != "resolution"]
    defs: dict[str, Any] = {n: _float_field(n, n.replace("_", " ")) for n in names}
    defs["resolution"] = (dict[str, str], Field(default_factory=dict, description=(
        "metric -> why the sampling cannot support it (null metric unless the reason starts with 'approximate')")))
    return create_model("MetricValues", __config__=ConfigDict(extra="allow"), **defs)


MetricValues = _metric_values_model()


class TrackingOut(_Open):
    verdict: str = Field(description="good | poor | unknown")
    reasons: list[str] = Field(default_factory=list)


class FindingOut(_Open):
    code: str
    channel: str | None = None
    message: str = ""


def _event_model() -> type[BaseModel]:
    hints = typing.get_type_hints(Event)
    defs: dict[str, Any] = {}
    for name in dict.fromkeys([*EVENT_COLUMNS, *hints]):
        if name == "tracking":
            defs[name] = (TrackingOut | None, None)
        elif name in ("index",):
            defs[name] = (int, ...)
        elif name in ("kind", "exclusion"):
            defs[name] = (str | None, None)
        elif name in ("included", "from_coast", "pedal_corroborated"):
            defs[name] = (bool | None, None)
        elif hints.get(name) in (float, float | None, int, int | None) or unit_of(name) != "-":
            defs[name] = _float_field(name, name.replace("_", " "))
        else:
            defs[name] = (Any, None)
    defs.update(error=(str | None, Field(default=None, description="why the event has no metrics")),
                has_series=(bool, False), has_metrics=(bool, False))
    return create_model("EventOut", __config__=ConfigDict(extra="allow"), **defs)


EventOut = _event_model()


class EventMetricsOut(_Open):
    """One event's metrics: ``measured``, ``simulated`` and ``difference`` (sim - meas), SI units."""

    event_index: int
    kind: str | None = None
    t_cross_s: float | None = Field(default=None, description="torque zero crossing (s)")
    measured: MetricValues  # type: ignore[valid-type]
    simulated: MetricValues  # type: ignore[valid-type]
    difference: MetricValues  # type: ignore[valid-type]
    rms_rpm: float | None = Field(default=None, description="aligned RMS error (rpm)")
    nrmse: float | None = Field(default=None, description="aligned RMS error over the measured range (-)")
    bias_rpm: float | None = Field(default=None, description="mean sim - meas (rpm)")
    samples: int | None = None
    sim_gap_open_time_s: float | None = Field(default=None, description="simulated gap-open time (s)")
    tracking: TrackingOut | None = None


class MetricSummaryOut(_Open):
    measured_median: float | None = None
    simulated_median: float | None = None
    difference_median: float | None = None
    difference_mean: float | None = None
    events: int = 0


class MetricsSummaryOut(_Open):
    events: int = 0
    included: int = 0
    excluded: int = 0
    with_metrics: int = 0
    tip_in: int = 0
    tip_out: int = 0
    offset_ms: float | None = Field(default=None, description="torque-to-speed offset applied (ms)")
    offset_applied: bool | None = None
    offset_correlation: float | None = None
    metrics: dict[str, MetricSummaryOut] = Field(default_factory=dict, description="metric -> medians over events")
    findings: list[FindingOut] = Field(default_factory=list)
    tracking: TrackingOut | None = None
    whole_rms_rpm: float | None = Field(default=None, description="whole-log RMS error (rpm)")
    whole_nrmse: float | None = None


class IntervalOut(BaseModel):
    """A value with its 90 % interval."""

    value: float | None = None
    lo: float | None = None
    hi: float | None = None


class BaseParameterOut(_Open):
    name: str
    label: str = ""
    ratio: float | None = Field(default=None, description="identified / the file's value (-)")
    lo: float | None = None
    hi: float | None = None
    value: float | None = None
    nominal: float | None = None
    unit: str = ""


class DecisionOut(_Open):
    status: str = Field(description="explained | partial | ambiguous | none_of_candidates | no_significant_gap | "
                                    "insufficient_data | base_parameters")
    top: list[str] = Field(default_factory=list, description="effect ids of the chosen fit")
    confusable: list[str] | None = None
    reason: str = ""
    residual_to_noise_before: IntervalOut | None = None
    explained_share: IntervalOut | None = None
    heldout_shrink: IntervalOut | None = None
    residual_to_noise_after: float | None = None
    residual_rms_rpm_before: float | None = Field(default=None, description="held-out residual RMS, baseline (rpm)")
    residual_rms_rpm_after: float | None = Field(default=None, description="held-out residual RMS, chosen fit (rpm)")
    base_parameters: list[BaseParameterOut] = Field(default_factory=list)
    identify_first: bool | None = None


class TradeOffOut(BaseModel):
    params: list[str]
    correlation: float | None = None


class FitOut(_Open):
    effects: list[str] = Field(default_factory=list)
    params: dict[str, dict[str, float | None]] = Field(default_factory=dict,
                                                       description="effect -> parameter -> value (SI)")
    nuisance: dict[str, float | None] = Field(default_factory=dict)
    at_bound: list[str] = Field(default_factory=list)
    trade_offs: list[TradeOffOut] = Field(default_factory=list)


class HeldoutScoreOut(_Open):
    shrink: IntervalOut | None = None
    explained_share: IntervalOut | None = None
    improved_fraction: float | None = None
    significant: bool | None = None
    residual_to_noise: float | None = None
    residual_rms_rpm: float | None = None


class CandidateOut(_Open):
    id: str
    title: str = ""
    effects: list[str] = Field(default_factory=list)
    fit: FitOut
    heldout: HeldoutScoreOut
    phases: dict[str, IntervalOut] = Field(default_factory=dict)
    bands: dict[str, IntervalOut] = Field(default_factory=dict)


class SplitOut(_Open):
    seed: int
    calibration: list[int]
    heldout: list[int]


class NoiseFloorOut(_Open):
    sigma_rpm: float | None = Field(default=None, description="white noise standard deviation (rpm)")
    quant_step_rpm: float | None = None
    period_s: float | None = None
    n_samples: int | None = None


class DiagnosisReportOut(_Open):
    """The diagnosis report (schema lashscope.diagnosis/1, docs/diagnosis.md)."""

    schema_: str = Field(alias="schema")
    vehicle: str
    model: str
    split: SplitOut
    noise_floor: NoiseFloorOut
    decision: DecisionOut
    baseline: FitOut | None = None
    candidates: list[CandidateOut] = Field(default_factory=list)
    pairs: list[CandidateOut] = Field(default_factory=list)
    findings: list[FindingOut] = Field(default_factory=list)
    candidates_not_applicable: dict[str, str] = Field(default_factory=dict)
    elapsed_s: float | None = None

    model_config = ConfigDict(extra="allow", populate_by_name=True, serialize_by_alias=True)


class DiagnosisValidationOut(_Open):
    status: str | None = None
    log_id: str | None = None
    events: int | None = None
    shrink: IntervalOut | None = None
    explained_share: IntervalOut | None = None
    improved_fraction: float | None = None
    residual_to_noise_baseline: float | None = None
    residual_to_noise_augmented: float | None = None
    error: ErrorOut | None = None


class MedianIntervalOut(BaseModel):
    median: float | None = None
    lo: float | None = None
    hi: float | None = None


class FleetLogOut(_Open):
    """One log of a vehicle: its medians with intervals; ``analyses`` of it on this server."""

    log_hash: str
    log_name: str | None = None
    log_id: str | None = None
    events: int
    time: str | None = Field(default=None, description="first event's absolute time (UTC), null without a log clock")
    tracking: str | None = None
    total_lash_deg: MedianIntervalOut = Field(description="motor-referred total lash estimate (deg)")
    ripple_rpm: MedianIntervalOut = Field(description="measured fluctuation (rpm)")
    analyses: list[dict[str, Any]] = Field(default_factory=list)


class FleetWeekOut(BaseModel):
    week: str
    events: int
    median: float | None = None


class FleetVehicleOut(_Open):
    vehicle: str
    events: int
    logs: int
    events_with_gap_open_time: int = 0
    events_poor_tracking: int = 0
    first: str | None = None
    last: str | None = None
    gap_open_time_ms: MedianIntervalOut = Field(description="median measured gap-open time (ms)")
    total_lash_deg: MedianIntervalOut = Field(description="median total lash, motor-referred (deg)")
    ripple_rpm: MedianIntervalOut = Field(description="median measured fluctuation (rpm)")
    weekly_ripple_rpm: list[FleetWeekOut] = Field(default_factory=list)
    flags: list[str] = Field(default_factory=list, description="why the vehicle is outside the fleet band")
    per_log: list[FleetLogOut] = Field(default_factory=list)


class FleetBandOut(BaseModel):
    center: float
    lo: float
    hi: float


class EventsOut(_Open):
    """``/analyses/{id}/events``: every tip-in/tip-out (``Event`` fields, ``exclusion`` says why one is left out)."""

    analysis_id: str
    count: int
    events: list[EventOut]  # type: ignore[valid-type]


class MetricsOut(_Open):
    """``/analyses/{id}/metrics``: per event ``measured``, ``simulated``, ``difference`` (sim - meas), SI units."""

    analysis_id: str
    summary: MetricsSummaryOut
    offset: dict[str, Any]
    whole: dict[str, Any] | None
    events: list[EventMetricsOut]
    notes: list[str]
    tracking: TrackingOut | None = None
    sampling: dict[str, Any] | None = None
    units: dict[str, str] = Field(default_factory=dict, description="metric -> unit of its values (SI)")


class SignalsOut(BaseModel):
    analysis_id: str
    signals: dict[str, dict[str, Any]] = Field(description="channel -> unit, samples, interp, t_start_s, t_end_s")


class ToleranceOut(_Open):
    n: int
    seed: int
    sampled_fields: list[str] = Field(default_factory=list)
    events: list[dict[str, Any]] = Field(default_factory=list)


class FleetOut(_Open):
    """The fleet report (docs/fleet.md): per vehicle the lash and ripple estimates with intervals, the
    fleet's bands and the vehicles outside them."""

    store: str
    vehicles: list[FleetVehicleOut] = Field(default_factory=list)
    bands: dict[str, FleetBandOut | None] = Field(default_factory=dict)
    band_k: float
    interval_level: float
    poor_tracking: dict[str, Any] = Field(default_factory=dict, description=(
        "events and logs whose tracking verdict is poor, and whether they are in the figures"))
    units: dict[str, str] = Field(default_factory=dict)
    flagged: list[str] = Field(default_factory=list)


class GapSensitivityOut(_Open):
    name: str
    version: int
    sensitivity_unit: str | None = None


class JobStateOut(BaseModel):
    """Where a result computed on request stands: ``not_started``, ``queued``, ``running``, ``done`` or
    ``failed`` (with ``error``); a read that never starts work."""

    status: str
    progress: float = 0.0
    stage: str = ""
    job_id: str | None = None
    error: ErrorOut | None = None
    elapsed_s: float | None = None  # while running: seconds since it started (job_timing)
    eta_s: float | None = None  # while running: seconds left at its pace so far, None early on


class GapSensitivityJobOut(BaseModel):
    """A gap sensitivity being computed: poll ``GET /vehicles/{name}/gap-sensitivity`` until it answers 200."""

    name: str
    version: int
    job_id: str
    status: str
    stage: str
    progress: float


class LiveSessionOut(_Open):
    """A live session's status (frames/s, dropped frames, bus and decode errors, bus state)."""

    id: str
    state: str
    bus: dict[str, Any]
    started_at: str | None
    frames_received: int
    frames_per_s: float
    events: int


class LiveEventsOut(BaseModel):
    session_id: str
    count: int
    events: list[dict[str, Any]]


class DiagnosisOut(_Open):
    """Status of a diagnosis; ``report`` (schema lashscope.diagnosis/1, docs/diagnosis.md) once done."""

    id: str
    analysis_id: str
    status: str
    progress: float = 0.0
    stage: str = ""
    elapsed_s: float | None = None  # while running: seconds since it started
    eta_s: float | None = None  # while running: seconds left at its pace so far, None early on
    plots: list[str] = Field(default_factory=list)
    report: DiagnosisReportOut | None = None
    validation: DiagnosisValidationOut | None = None


class AppliedOut(BaseModel):
    vehicle: str
    version: int
    created: bool
    effects: dict[str, dict[str, float]]
    from_: str = Field(alias="from")

    model_config = ConfigDict(populate_by_name=True)


class EffectOut(BaseModel):
    id: str
    title: str
    model: str
    params: list[str]


class FieldChange(BaseModel):
    field: str
    a: Any
    b: Any
    changed: bool
    delta: float | None = Field(description="b - a for numbers")
    ratio: float | None = Field(description="b / a for numbers (null when a is 0)")


class FigureChange(BaseModel):
    key: str = Field(description="stiffness, freq, damping, mass, lash, torque_gain")
    label: str
    unit: str
    a: float | None = Field(description="null where the chain has no oscillating mode")
    b: float | None
    ratio: float | None = Field(description="b / a")


class VehicleCompareOut(BaseModel):
    name: str
    a: int
    b: int
    changed: int
    fields: list[FieldChange]
    files_changed: list[str]
    figures: list[FigureChange] = Field(description="what the base parameters are reported as, both versions")
    provenance: dict[str, dict[str, Any] | None] = Field(
        description="'a'/'b': the version's [provenance] table when it was identified, else null")


class BatchCreate(BaseModel):
    """``POST /batches``: stored logs through the fleet batch pipeline (docs/fleet.md) as one job."""

    log_ids: list[str] = Field(min_length=1, max_length=1000, description="ids of uploaded logs (no repeats)")
    vehicle: str
    vehicle_version: int | None = None
    vehicle_id: str | None = Field(default=None, max_length=200,
                                   description="the fleet's name of the car (default: the vehicle's name)")
    options: dict[str, Any] = Field(default_factory=dict, description="AnalysisOptions fields (app.pipeline)")
    diagnose: bool = Field(default=False, description="also diagnose each log (all candidates; slower)")


class IdentificationCreate(BaseModel):
    """``POST /identifications``: identify a vehicle's base parameters from uploaded logs (one job)."""

    log_ids: list[str] = Field(min_length=1, max_length=50, description="ids of uploaded logs of the car (fitted)")
    validate_log_ids: list[str] = Field(default_factory=list, max_length=10,
                                        description="withheld drives: tracking before and after, never fitted")
    vehicle: str
    vehicle_version: int | None = None
    params: list[str] = Field(default_factory=lambda: ["stiffness", "damping", "mass", "lash"], min_length=1,
                              max_length=4, description="base parameters to fit: stiffness, damping, mass, lash")
    seed: int = Field(default=0, ge=0, le=2**31 - 1)


class IdentifiedParamOut(_Open):
    """One identified quantity: value with its interval (90 %) and the file's value, in ``unit``."""

    name: str
    label: str
    unit: str
    value: float | None
    lo: float | None
    hi: float | None
    nominal: float | None
    identified: bool = Field(description="false: the data do not pin it down; it stays at the file's value")
    at_bound: bool = Field(description="the fit rests on a prior bound: not trusted")
    named: bool = Field(description="off the file: identified, interval excluding the file's value, a change "
                                    "large enough to matter")
    note: str = ""


class ModalOut(_Open):
    """The model-free first torsional mode pooled over the event windows."""

    freq_hz: float
    freq_ci: list[float]
    zeta: float
    zeta_ci: list[float]
    n_windows: int
    n_used: int


class ContactLawOut(_Open):
    """How the identified vehicle's contact dampers engage (``Vehicle.contact_damping``), as the log chose."""

    contact_damping: str = Field(description="limited | full: the law the identified vehicle carries")
    file: str = Field(description="the vehicle file's law")
    changed: bool
    residual_to_noise: dict[str, float] = Field(description="law -> the identified vehicle's calibration residual "
                                                "(times the noise floor) under it")


class IdentificationResultOut(_Open):
    """The result of an identification (``lashscope identify --json``)."""

    vehicle: str
    params: dict[str, IdentifiedParamOut]
    named: list[str]
    not_identified: list[str]
    modal: ModalOut | None = None
    nuisance: dict[str, float]
    residual_to_noise_before: float
    residual_to_noise_after: float
    events: int
    contact_damping: ContactLawOut | None = Field(default=None, description="the contact law the log chose; null "
                                                  "where the vehicle has no damped clearance to choose on")
    validation: dict[str, Any] = Field(default_factory=dict, description="withheld drives: nrmse_before, "
                                       "nrmse_after, verdict_before, verdict_after, per drive before/after")


class VehicleJobOut(BaseModel):
    """What every job over a vehicle's logs reports: its id, status, progress and stage, the job row, the vehicle."""

    id: str
    status: str
    progress: float
    stage: str
    job: JobOut
    vehicle: str
    vehicle_version: int


class IdentificationOut(VehicleJobOut):
    """An identification job: status and progress; ``result`` once done; ``applied`` once stored as a version."""

    log_ids: list[str]
    validate_log_ids: list[str]
    params: list[str]
    result: IdentificationResultOut | None = None
    applied: dict[str, Any] | None = None
    links: dict[str, str]


class BatchOut(VehicleJobOut):
    """A batch job: its status and progress; ``counts`` of logs ok / failed / pending; ``summary`` once done."""

    vehicle_id: str
    logs: int
    counts: dict[str, int]
    summary: dict[str, Any] | None = None
    links: dict[str, str]


class BatchLogOut(_Open):
    """One log of a batch: ``status`` ok | failed | pending; events, summary and tracking when ok;
    ``code`` and ``message`` when failed (the record of docs/fleet.md, named by log id)."""

    log_id: str
    filename: str
    status: str


class BatchLogsOut(BaseModel):
    batch_id: str
    count: int
    logs: list[BatchLogOut]


class ChannelEvidenceOut(BaseModel):
    """One proposed channel and what the log says about it (app.signal_proposal.ChannelEvidence)."""

    channel: str
    source: str = Field(description="Message.Signal")
    dbc_unit: str
    unit: str = Field(description="the canonical unit")
    factor: float = Field(description="DBC unit -> canonical unit")
    invert: bool
    chosen_by: str = Field(description="suggested | user")
    score: float | None = Field(description="name/unit/rate score of the suggester (null: the user's choice)")
    reasons: list[str]
    samples: int
    rate_hz: float | None
    minimum: float | None = Field(description="decoded, in the canonical unit")
    maximum: float | None
    correlation: float | None
    correlation_with: str
    sign: str


class SignalMapProposalOut(BaseModel):
    log_id: str
    database: str
    log_format: str
    frames: int
    duration_s: float
    missing: list[str] = Field(description="channels every analysis needs that no signal was found for")
    channels: list[ChannelEvidenceOut]
    candidates: dict[str, list[str]] = Field(description="per channel, the suggester's best signals")
    signal_map_toml: str = Field(description="the proposed map, for POST /vehicles (field signal_map)")


class ResidualByEvent(BaseModel):
    index: int
    kind: str
    t_event_s: float | None
    before: float | None = Field(description="held-out residual / noise energy of the baseline (1 = noise)")
    after: float | None = Field(description="the same with the chosen fit (null: nothing fitted)")


class ResidualByPhase(BaseModel):
    phase: str
    samples: int
    before: float | None
    after: float | None


class ResidualByBand(BaseModel):
    band: str
    before: float | None = Field(description="share of the baseline's held-out residual energy in this band")
    after: float | None


class HeldoutOverlay(BaseModel):
    """Speed of one held-out event on time from its torque zero crossing (s); rpm."""

    index: int
    kind: str
    t_event_s: float | None
    t_s: list[float | None]
    measured_rpm: list[float | None]
    baseline_rpm: list[float | None]
    fitted_rpm: list[float | None] | None
    gap_open_s: float | None
    gap_close_s: float | None


class DiagnosisChartsOut(BaseModel):
    """``/diagnoses/{id}/charts``: the numbers behind the diagnosis plots (lashscope.diagnosis-charts/1)."""

    schema_: str = Field(alias="schema")
    status: str
    top: list[str]
    fitted: str | None = Field(description="the fit shown as 'after': the chosen effect(s), the best one not "
                                           "attributed, or the identified base parameters")
    noise_sigma_rpm: float | None
    heldout: int
    events: list[ResidualByEvent]
    phases: list[ResidualByPhase]
    bands: list[ResidualByBand]
    overlays: list[HeldoutOverlay]

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)
