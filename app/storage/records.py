"""Rows the store hands out: plain frozen dataclasses, no database handles inside."""

from __future__ import annotations

import enum
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


class JobStatus(enum.StrEnum):
    QUEUED = "queued"
    RUNNING = "running"
    DONE = "done"
    FAILED = "failed"


@dataclass(frozen=True)
class LogRecord:
    id: str  # "log_" + first 16 hex digits of the content hash: the same bytes always get the same id
    sha256: str
    filename: str
    size_bytes: int
    format: str
    created_at: str  # ISO 8601 UTC
    path: Path
    frames: int
    duration_s: float
    start_time: str | None
    issues: list[dict[str, Any]] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class VehicleRecord:
    name: str
    version: int
    created_at: str
    sha256: str  # of driveline + database + signal map, so an identical re-upload is not a new version
    driveline_path: Path
    database_path: Path
    signal_map_path: Path
    summary: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class JobRecord:
    id: str
    kind: str  # "analysis" | "gap_sensitivity"
    subject: str  # analysis id, or "vehicle-name@version"
    status: JobStatus
    progress: float  # 0..1
    stage: str
    attempts: int
    created_at: str
    updated_at: str
    started_at: str | None = None
    finished_at: str | None = None
    error_code: str | None = None
    error_detail: str | None = None
    owner_pid: int | None = None
    lease_owner: str | None = None  # the runner holding the job (app.storage.jobtable)
    lease_until: float | None = None  # epoch seconds; past it the job is taken back


@dataclass(frozen=True)
class AnalysisRecord:
    id: str
    log_id: str
    vehicle_name: str
    vehicle_version: int
    options: dict[str, Any]
    created_at: str
    job: JobRecord
    result_dir: Path
    summary: dict[str, Any] = field(default_factory=dict)
