"""Response and request bodies (published in the OpenAPI document)."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from app.storage.records import AnalysisRecord, JobRecord, LogRecord, VehicleRecord


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

    @classmethod
    def of(cls, j: JobRecord) -> JobOut:
        err = ErrorOut(detail=j.error_detail or "", code=j.error_code) if j.error_code else None
        return cls(id=j.id, status=j.status.value, progress=j.progress, stage=j.stage, attempts=j.attempts,
                   created_at=j.created_at, started_at=j.started_at, finished_at=j.finished_at, error=err)


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


class EventsOut(_Open):
    """``/analyses/{id}/events``: every tip-in/tip-out (``Event`` fields, ``exclusion`` says why one is left out)."""

    analysis_id: str
    count: int
    events: list[dict[str, Any]]


class MetricsOut(_Open):
    """``/analyses/{id}/metrics``: per event ``measured``, ``simulated``, ``difference`` (sim - meas), SI units."""

    analysis_id: str
    summary: dict[str, Any]
    offset: dict[str, Any]
    whole: dict[str, Any] | None
    events: list[dict[str, Any]]
    notes: list[str]
    tracking: dict[str, Any] | None = None
    sampling: dict[str, Any] | None = None


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
    vehicles: list[dict[str, Any]] = Field(default_factory=list)
    bands: dict[str, Any] = Field(default_factory=dict)
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
    plots: list[str] = Field(default_factory=list)
    report: dict[str, Any] | None = None
    validation: dict[str, Any] | None = None


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


class VehicleCompareOut(BaseModel):
    name: str
    a: int
    b: int
    changed: int
    fields: list[FieldChange]
    files_changed: list[str]


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
    fitted: str | None = Field(description="the fit shown as 'after': the chosen effect(s), or the best one not attributed")
    noise_sigma_rpm: float | None
    heldout: int
    events: list[ResidualByEvent]
    phases: list[ResidualByPhase]
    bands: list[ResidualByBand]
    overlays: list[HeldoutOverlay]

    model_config = ConfigDict(populate_by_name=True, serialize_by_alias=True)
