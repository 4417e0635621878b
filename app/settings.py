"""Service settings from the environment (``LASHSCOPE_*``), read once behind :func:`get_settings`.

``LASHSCOPE_DATA_DIR``          where SQLite and the files live (default ``./lashscope-data``)
``LASHSCOPE_MAX_UPLOAD_MB``     upload size cap in MiB (default 1024); larger uploads get 413
``LASHSCOPE_MAX_INFLATED_MB``   a gzipped log inflates to at most this many MiB (default 4096) and 32x its compressed
                              size; past it the log is refused (code ``inflated_too_large``, 413)
``LASHSCOPE_VALIDATE_CPU_S``    an uploaded log is read once to validate it; past this many CPU seconds it is refused
                              (422 ``validation_limit``; default 8: BLF/MF4 of several GB, text logs of ~80 MB)
``LASHSCOPE_CORS_ORIGINS``      comma-separated origins allowed by CORS (default none)
``LASHSCOPE_ANALYSIS_WORKERS``  background analyses run at the same time (default 1)
``LASHSCOPE_JOB_MAX_ATTEMPTS``  a job cut off by a crash is re-run until it has started this often
``LASHSCOPE_JOB_TIMEOUT_S``     a job's worker process is killed after this wall time and the job fails (default 600)
``LASHSCOPE_JOB_LEASE_S``       a running job's lease (default 10 s, renewed every third); after a crash its job is
                              resumed once the lease has run out, never while its runner may still live
``LASHSCOPE_DIAGNOSIS_TIMEOUT_S``  a diagnosis' (or validation's) worker process is killed after this wall time
                                 and it fails (default 1800)
``LASHSCOPE_BATCH_TIMEOUT_S``   a batch job's worker process is killed after this wall time (default 3600)
``LASHSCOPE_DBC_DIR``           the project's DBC files and signal maps (default: ``dbc/`` in the source tree)
``LASHSCOPE_SHUTDOWN_GRACE_S``  on stop, open requests (e.g. live streams) get this long before they are cut
``LASHSCOPE_STORE_URL``         the store as a URL (``sqlite:////srv/ls/db.sqlite3``, or ``postgresql://user@host/db``
                              shared by several servers, its files in ``?files=DIR`` or the data directory);
                              default: the data directory's SQLite
``LASHSCOPE_ALLOWED_HOSTS``     Host header names accepted besides the loopback names (comma-separated; ``*``: any)
``LASHSCOPE_INSECURE``          serve on a non-loopback address without API keys (default off: refused)
``LASHSCOPE_MAX_JSON_KB``       body cap of every request but the uploads, in KiB (default 1024); past it 413
``LASHSCOPE_UPLOAD_IDLE_S``     an upload that sends nothing for this long is dropped (408, partial file removed)
``LASHSCOPE_MAX_QUEUED_JOBS``   new jobs are refused (429 ``queue_full``) while this many wait (default 32)
``LASHSCOPE_KEY_RATE_PER_S``    requests a second per API key (bursts of two seconds' worth); past it 429 (0: off)
``LASHSCOPE_CLIENT_RATE_PER_S`` requests a second per client address for requests without a key (default 200; 0: off)
``LASHSCOPE_LIVE_CHANNELS``     live buses a client may open, ``interface:channel`` or ``interface:*`` (comma-separated)
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

SOURCE_ROOT = Path(__file__).resolve().parents[1]


def default_dbc_dir() -> Path:
    for candidate in (SOURCE_ROOT / "dbc", Path.cwd() / "dbc"):
        if candidate.is_dir():
            return candidate
    return SOURCE_ROOT / "dbc"


class Settings(BaseSettings):
    model_config = SettingsConfigDict(env_prefix="LASHSCOPE_", extra="ignore")

    data_dir: Path = Path("lashscope-data")
    max_upload_mb: float = Field(default=1024.0, gt=0)
    max_inflated_mb: float = Field(default=4096.0, gt=0)
    validate_cpu_s: float = Field(default=8.0, gt=0)  # CPU seconds the server spends validating one upload
    upload_drain_mb: float = Field(default=64.0, ge=0)  # read and discard this much of an oversized body before 413
    cors_origins: Annotated[list[str], NoDecode] = Field(default_factory=list)
    analysis_workers: int = Field(default=1, ge=1, le=16)
    job_max_attempts: int = Field(default=2, ge=1)
    job_timeout_s: float = Field(default=600.0, gt=0)
    job_lease_s: float = Field(default=10.0, ge=1)  # a crashed server's jobs are resumed this long after
    diagnosis_timeout_s: float = Field(default=1800.0, gt=0)  # a whole-library fit on a long log takes minutes
    batch_timeout_s: float = Field(default=3600.0, gt=0)  # a batch analyses many logs in one job
    dbc_dir: Path = Field(default_factory=default_dbc_dir)
    series_cache_entries: int = Field(default=256, ge=0)
    series_cache_mb: float = Field(default=64.0, ge=0)  # rendered series responses kept in memory
    shutdown_grace_s: int = Field(default=5, ge=0)  # a live event stream never ends by itself
    host: str = "127.0.0.1"
    port: int = Field(default=8000, ge=0, le=65535)
    store_url: str | None = None
    allowed_hosts: Annotated[list[str], NoDecode] = Field(default_factory=list)
    insecure: bool = False
    max_json_kb: float = Field(default=1024.0, gt=0)
    upload_idle_s: float = Field(default=60.0, gt=0)
    max_queued_jobs: int = Field(default=32, ge=1)
    key_rate_per_s: float = Field(default=100.0, ge=0)  # per API key; 0: no limit
    client_rate_per_s: float = Field(default=200.0, ge=0)  # per client address, requests without a key; 0: off
    live_channels: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["virtual:*", "tcp_loopback:*", "socketcan:*"])

    @field_validator("cors_origins", "allowed_hosts", "live_channels", mode="before")
    @classmethod
    def _split_origins(cls, v: object) -> object:
        if isinstance(v, str):
            return [o.strip() for o in v.split(",") if o.strip()]
        return v

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1024 * 1024)

    @property
    def max_json_bytes(self) -> int:
        return int(self.max_json_kb * 1024)

    @property
    def job_timeouts(self) -> dict[str, tuple[float, str]]:
        """Wall time (s) of the job kinds that do not use ``job_timeout_s``, with the setting that names it."""
        diagnosis = (self.diagnosis_timeout_s, "LASHSCOPE_DIAGNOSIS_TIMEOUT_S")
        return {"diagnosis": diagnosis, "validation": diagnosis,
                "batch": (self.batch_timeout_s, "LASHSCOPE_BATCH_TIMEOUT_S")}

    @property
    def store_location(self) -> str:
        """What :func:`app.storage.url.open_store` opens: the URL if one is set, else the data directory."""
        return self.store_url or str(self.data_dir)


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read from the environment on first use."""
    return Settings()
