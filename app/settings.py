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
``LASHSCOPE_INSECURE``          serve without API keys on a non-loopback address, or after every key was revoked
                              (default off: refused, and closed)
``LASHSCOPE_MAX_JSON_KB``       body cap of every request but the uploads, in KiB (default 1024); past it 413
``LASHSCOPE_UPLOAD_IDLE_S``     an upload that sends nothing for this long is dropped (408, partial file removed)
``LASHSCOPE_MAX_QUEUED_JOBS``   new jobs are refused (429 ``queue_full``) while this many wait (default 32)
``LASHSCOPE_KEY_RATE_PER_S``    requests a second per API key; past it 429 (0: off)
``LASHSCOPE_CLIENT_RATE_PER_S`` requests a second per client address for requests without a key (default 200; 0: off)
``LASHSCOPE_AUTH_FAILURE_RATE_PER_S``  failed authentications a second per client address (default 2; 0: off); past
                              it 429, and that client's keys are not even checked until its bucket refills
``LASHSCOPE_RATE_BURST_S``      both rates allow bursts of this many seconds' worth (default 10: a dashboard opening
                              views for many viewers at once), then hold to the rate
``LASHSCOPE_MAX_URL_KB``        request URL cap in KiB (default 8); past it 414 ``url_too_long``
``LASHSCOPE_MAX_HEADER_KB``     cap of a request's line and headers together, in KiB (default 64); past it 431
``LASHSCOPE_MAX_HEADERS``       header lines a request may have (default 100); past it 431 ``too_many_headers``
``LASHSCOPE_HEADER_TIMEOUT_S``  a request's head must arrive within this (default 10 s); then 408 ``header_timeout``
``LASHSCOPE_BODY_TIMEOUT_S``    a request's body must arrive within this of its head, however slowly it comes
                              (default 900 s: 1 GiB at 1.2 MB/s); then 408 ``body_timeout``
``LASHSCOPE_KEEP_ALIVE_S``      an idle kept-alive connection is closed after this (default 5 s)
``LASHSCOPE_MAX_CONNECTIONS``   connections open at once (default 1000; the longest waiting without a request makes
                              room for a new one)
``LASHSCOPE_MAX_CLIENT_CONNECTIONS``  connections per client address (default 64; past it 429
                                    ``too_many_connections``); trusted proxies are exempt
``LASHSCOPE_TRUSTED_PROXIES``   reverse proxies (addresses or networks, comma-separated) whose ``X-Forwarded-For`` and
                              ``X-Forwarded-Proto`` are believed; from anyone else they are ignored (default none)
``LASHSCOPE_LIVE_CHANNELS``     live buses a client may open, ``interface:channel`` or ``interface:*`` (comma-separated;
                              default ``virtual:*,tcp_loopback:127.0.0.1:29536,socketcan:*``: of the loopback
                              hubs only the one on the default port, so a client cannot probe local ports)
``LASHSCOPE_LIVE_INTERFACES``   python-can interfaces a live session may use (comma-separated; replaces the default set)
``LASHSCOPE_EVENT_STORE``       Parquet event store the service's analyses also write (app.fleet.hook; ``off``: none;
                              ``lashscope serve`` sets ``<data dir>/events`` for its workers unless it is set)
``LASHSCOPE_RATINGS``           rating model file scoring every analysed event (app.ratings_file; default none)
``LASHSCOPE_MF4_NATIVE``        read MF4 with the project's numpy reader where the layout allows (default true;
                              false: always through asammdf)

Values a process hands to the processes it starts (the event store, the rating model) are read when they are
used, with a fresh ``Settings()``; the server reads the rest once (:func:`get_settings`).
"""

from __future__ import annotations

import ipaddress
from functools import lru_cache
from pathlib import Path
from typing import Annotated

from pydantic import Field, field_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

SOURCE_ROOT = Path(__file__).resolve().parents[1]
DEFAULT_HUB_PORT = 29536  # app.live.loopback.DEFAULT_PORT, without importing python-can for the settings

IPNetwork = ipaddress.IPv4Network | ipaddress.IPv6Network


def parse_networks(entries: list[str]) -> tuple[IPNetwork, ...]:
    """Addresses and networks (``10.0.0.5``, ``10.0.0.0/8``, ``::1``) as networks; ``ValueError`` names a bad one."""
    nets = []
    for entry in entries:
        try:
            nets.append(ipaddress.ip_network(entry, strict=False))
        except ValueError:
            raise ValueError(f"{entry!r} is not an IP address or network (e.g. 10.0.0.5 or 10.0.0.0/8)") from None
    return tuple(nets)


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
    auth_failure_rate_per_s: float = Field(default=2.0, ge=0)  # wrong keys per client address; 0: off
    rate_burst_s: float = Field(default=10.0, gt=0)  # bucket depth of both rates, in seconds' worth
    max_url_kb: float = Field(default=8.0, gt=0)
    max_header_kb: float = Field(default=64.0, gt=0)
    max_headers: int = Field(default=100, ge=1)
    header_timeout_s: float = Field(default=10.0, gt=0)
    body_timeout_s: float = Field(default=900.0, gt=0)
    keep_alive_s: int = Field(default=5, ge=1)
    max_connections: int = Field(default=1000, ge=1)
    max_client_connections: int = Field(default=64, ge=1)
    trusted_proxies: Annotated[list[str], NoDecode] = Field(default_factory=list)
    live_channels: Annotated[list[str], NoDecode] = Field(
        default_factory=lambda: ["virtual:*", f"tcp_loopback:127.0.0.1:{DEFAULT_HUB_PORT}", "socketcan:*"])
    # address space of the process that reads an upload with a client's format description, or proposes a signal map
    bounded_memory_mb: int = Field(default=1536, ge=512)

    @field_validator("cors_origins", "allowed_hosts", "live_channels", "trusted_proxies", mode="before")
    @classmethod
    def _split_origins(cls, v: object) -> object:
        if isinstance(v, str):
            return [o.strip() for o in v.split(",") if o.strip()]
        return v

    live_interfaces: Annotated[list[str], NoDecode] = Field(default_factory=list)  # empty: the default set
    event_store: str = ""  # a directory; "", "0", "off", "none", "false": no event store
    ratings: str = ""  # a rating model file; "": no ratings
    mf4_native: bool = True

    @field_validator("live_interfaces", mode="before")
    @classmethod
    def _split_names(cls, v: object) -> object:
        return [o.strip() for o in v.split(",") if o.strip()] if isinstance(v, str) else v

    @field_validator("trusted_proxies")
    @classmethod
    def _networks(cls, v: list[str]) -> list[str]:
        parse_networks(v)
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
        return {"diagnosis": diagnosis, "validation": diagnosis, "identification": diagnosis,
                "batch": (self.batch_timeout_s, "LASHSCOPE_BATCH_TIMEOUT_S")}

    @property
    def store_location(self) -> str:
        """What :func:`app.storage.url.open_store` opens: the URL if one is set, else the data directory."""
        return self.store_url or str(self.data_dir)


@lru_cache(maxsize=1)
def get_settings() -> Settings:
    """The process-wide settings, read from the environment on first use."""
    return Settings()
