"""Many logs through the pipeline on Dask: per-log records, event rows, skip and resume by content hash.

Output directory::

    OUT/logs/<log sha256>.json     one record per log: status ok | failed, error code and message,
                                   summary, diagnosis outcome, time taken; written atomically
    OUT/events/...                 the event store (app.fleet.store), one file per log and partition

A log is done when its record exists; a re-run skips it (``retry_failed`` re-runs failed ones),
so a batch killed at any point resumes where it stopped: a log whose rows were written but not
its record is analysed again and its rows replaced (same file names). The client computes the
content hashes, the tasks (:func:`app.fleet.work.analyse_log`) only analyse, and the client
writes each result as it arrives, so a remote cluster needs read access to the logs and vehicle
files but no write access to ``OUT``.
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, TextIO

from app import atomic
from app.errors import AppError, InputError
from app.fleet.rows import event_rows
from app.fleet.store import compact, write_rows
from app.fleet.work import BatchSpec, analyse_log, warm_kernels
from app.log_source import content_hash, is_url, source_name

RECORD_FORMAT = 1


@dataclass(frozen=True)
class BatchConfig:
    out: Path
    spec: BatchSpec
    vehicle_id: str  # the fleet's name of the vehicle the logs come from
    vehicle_id_from_dir: bool = False  # use each log's parent folder name instead
    scheduler: str | None = None
    workers: int = 2  # 0: in-process, no Dask
    retry_failed: bool = False
    connect_timeout_s: float = 10.0


@dataclass
class BatchSummary:
    total: int = 0
    ok: int = 0
    failed: int = 0
    skipped: int = 0
    events: int = 0
    elapsed_s: float = 0.0
    failures: list[dict[str, Any]] = field(default_factory=list)
    timings_s: dict[str, float] = field(default_factory=dict)  # warm_kernels, cluster_start, analyse, compact
    partitions: set[Path] = field(default_factory=set)  # event-store folders written to


def expand_sources(patterns: Sequence[str]) -> list[str]:
    """Paths, globs (``**`` recursive) and URLs, in the given order, without repeats.

    A pattern with a wildcard that matches nothing raises InputError; a plain path that does not
    exist is kept, so the batch records it as a failed log (``file_not_found``).
    """
    out: list[str] = []
    for pattern in patterns:
        if not is_url(pattern) and glob.has_magic(pattern):
            hits = sorted(p for p in glob.glob(pattern, recursive=True) if os.path.isfile(p))
            if not hits:
                raise InputError(f"no log matches {pattern}")
            out.extend(hits)
        else:
            out.append(pattern)
    return list(dict.fromkeys(out))


def _write_json(path: Path, doc: dict[str, Any]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_text(path, json.dumps(doc, indent=1, allow_nan=False))


def record_path(out: Path, key: str) -> Path:
    return out / "logs" / f"{key}.json"


def read_record(out: Path, key: str) -> dict[str, Any] | None:
    try:
        doc: dict[str, Any] = json.loads(record_path(out, key).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc


def read_records(out: Path) -> dict[str, dict[str, Any]]:
    """Every per-log record of the batch output ``out`` written so far, by the log's key (content hash)."""
    found: dict[str, dict[str, Any]] = {}
    for path in sorted((out / "logs").glob("*.json")):
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError):  # removed meanwhile, or not ours
            continue
        found[path.stem] = doc
    return found


def _vehicle_of(source: str, cfg: BatchConfig) -> str:
    if not cfg.vehicle_id_from_dir:
        return cfg.vehicle_id
    parent = source.rstrip("/").rsplit("/", 2)[-2] if "/" in source else ""
    return parent or cfg.vehicle_id


@dataclass
class _Pending:
    source: str
    key: str  # content hash, or a hash of the name when the log cannot be read at all
    vehicle: str


def _store(out: Path, job: _Pending, result: dict[str, Any], cfg: BatchConfig,
           partitions: set[Path]) -> dict[str, Any]:
    """Write one task's rows and then its record (the record marks the log done)."""
    record: dict[str, Any] = {
        "format": RECORD_FORMAT, "log": job.source, "log_name": source_name(job.source), "log_hash": job.key,
        "vehicle": job.vehicle, "driveline": cfg.spec.inputs.vehicle.name, "status": result["status"],
        "elapsed_s": round(float(result.get("elapsed_s", 0.0)), 3),
        "cpu_s": round(float(result.get("cpu_s", 0.0)), 3),
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
    }
    if result["status"] == "ok":
        doc = result["doc"]
        rows = event_rows(doc, vehicle=job.vehicle, log_hash=job.key, log_name=record["log_name"],
                          source="batch", driveline=record["driveline"], diagnosis=result.get("diagnosis"))
        partitions.update(f.parent for f in write_rows(out / "events", rows, source="batch", log_hash=job.key))
        record.update(events=len(rows), summary=doc["summary"], tracking=doc["tracking"],
                      start_time=doc["ingest"].get("start_time"), diagnosis=result.get("diagnosis"))
    else:
        record.update(code=result["code"], message=result["message"])
    _write_json(record_path(out, job.key), record)
    return record


def _plan(sources: Sequence[str], cfg: BatchConfig, summary: BatchSummary,
          done: Callable[[dict[str, Any]], None]) -> list[_Pending]:
    """Hash every log (client side) and keep those not done yet; unreadable logs are recorded at once."""
    todo: list[_Pending] = []
    seen: set[str] = set()
    for source in sources:
        vehicle = _vehicle_of(source, cfg)
        try:
            key = content_hash(source)
        except AppError as exc:
            key = "name-" + hashlib.sha256(source.encode()).hexdigest()[:32]
            done(_store(cfg.out, _Pending(source, key, vehicle),
                        {"status": "failed", "code": exc.code, "message": str(exc)}, cfg, summary.partitions))
            continue
        if key in seen:
            summary.skipped += 1
            continue
        seen.add(key)
        prior = read_record(cfg.out, key)
        if prior is not None and (prior.get("status") == "ok" or not cfg.retry_failed):
            summary.skipped += 1
            continue
        todo.append(_Pending(source, key, vehicle))
    return todo


class Progress:
    """One status line on ``stream``: redrawn in place on a terminal, one line per log otherwise."""

    def __init__(self, total: int, stream: TextIO | None = None) -> None:
        self.total, self.stream = total, stream
        self.start = time.perf_counter()
        self.count = 0

    def update(self, summary: BatchSummary, name: str) -> None:
        if self.stream is None:
            return
        self.count += 1
        width = 24
        filled = int(width * self.count / max(self.total, 1))
        line = (f"[{'#' * filled}{'.' * (width - filled)}] {self.count}/{self.total}  ok {summary.ok}  "
                f"failed {summary.failed}  {time.perf_counter() - self.start:6.1f} s  {name}")
        tty = self.stream.isatty()
        self.stream.write(("\r" + line[:120].ljust(120)) if tty else line + "\n")
        if tty and self.count >= self.total:
            self.stream.write("\n")
        self.stream.flush()


def run_batch(sources: Sequence[str], cfg: BatchConfig, stream: TextIO | None = sys.stderr,
              on_record: Callable[[dict[str, Any]], None] | None = None, client: Any = None) -> BatchSummary:
    """Analyse ``sources`` (see :func:`expand_sources`) into ``cfg.out``; never stops for one bad log.

    ``on_record(record)`` is called as each log's record is written (the service's batch job reports
    its progress with it). ``client``: a connected ``distributed.Client`` to run on instead of
    connecting (or starting a local cluster) for this call -- for callers that run many batches, each
    of which would otherwise pay the connection and the workers' readiness check again."""
    clock = time.perf_counter()
    summary = BatchSummary(total=len(sources))
    progress = Progress(len(sources), stream)

    def done(record: dict[str, Any]) -> None:
        if record["status"] == "ok":
            summary.ok += 1
            summary.events += int(record.get("events", 0))
        else:
            summary.failed += 1
            summary.failures.append({k: record[k] for k in ("log", "code", "message")})
        progress.update(summary, record["log_name"])
        if on_record is not None:
            on_record(record)

    todo = _plan(sources, cfg, summary, done)
    progress.total = progress.count + len(todo)
    if todo and cfg.workers == 0 and not cfg.scheduler:
        for job in todo:
            done(_store(cfg.out, job, analyse_log(job.source, cfg.spec), cfg, summary.partitions))
    elif todo:
        _on_cluster(todo, cfg, done, summary, client)
    if summary.partitions:
        clock_c = time.perf_counter()
        compact(summary.partitions)  # one file per partition: queries pay per file
        summary.timings_s["compact"] = time.perf_counter() - clock_c
    summary.elapsed_s = time.perf_counter() - clock
    return summary


def _on_cluster(todo: list[_Pending], cfg: BatchConfig, done: Callable[[dict[str, Any]], None],
                summary: BatchSummary, client: Any = None) -> None:
    from app.fleet.cluster import dask_client  # lazy: Dask (an optional extra) only on a cluster

    if client is not None:
        _run_on(client, todo, cfg, done, summary, time.perf_counter())
        return
    if not cfg.scheduler:  # the local workers then load the kernels from numba's cache instead of compiling them
        summary.timings_s["warm_kernels"] = warm_kernels()
    clock = time.perf_counter()
    with dask_client(cfg.scheduler, cfg.workers, cfg.connect_timeout_s) as connected:
        _run_on(connected, todo, cfg, done, summary, clock)


def _run_on(client: Any, todo: list[_Pending], cfg: BatchConfig, done: Callable[[dict[str, Any]], None],
            summary: BatchSummary, clock: float) -> None:
    from distributed import as_completed  # lazy: Dask (an optional extra) only on a cluster

    from app.fleet.plugin import WarmWorker  # lazy: imports distributed

    timings = summary.timings_s
    client.register_plugin(WarmWorker())  # every worker imports and loads the kernels once (a no-op when warm)
    timings["cluster_start"] = time.perf_counter() - clock
    # a key of its own per call: with the content-hash key, a second batch on the same client could scatter
    # the same spec while the first one's release was still on its way, and lose it ("lost dependencies")
    spec = client.scatter(cfg.spec, broadcast=True, hash=False)
    futures = {client.submit(analyse_log, job.source, spec, key=f"lashscope-{job.key}", pure=False): job
               for job in todo}
    for future in as_completed(futures, loop=client.loop):
        job = futures[future]
        try:
            result = future.result()
        except Exception as exc:  # the worker died (KilledWorker) or the task could not run there
            result = {"status": "failed", "code": "worker_error", "message": f"{type(exc).__name__}: {exc}"}
        done(_store(cfg.out, job, result, cfg, summary.partitions))
        future.release()
    timings["analyse"] = time.perf_counter() - clock - timings["cluster_start"]
