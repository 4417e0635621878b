"""The store's rows in SQL and its content in files: everything the SQLite and PostgreSQL stores share.

Layout of the files directory (``root``)::

    <root>/tmp/                       temporary files: uploads in progress, inflated logs (app.tempfiles;
                                      removed on failure, at startup and when their writer is gone)
    <root>/logs/<sha256><.ext>        uploaded logs, one file per distinct content
    <root>/logs/<sha256><.ext>.format.toml  the format description uploaded with a text log (if any)
    <root>/vehicles/<name>/v<N>/      driveline.toml, database<.ext>, signals.map.toml
    <root>/analyses/<id>/             results written by the pipeline (atomic rename on completion)
    <root>/jobs/<id>/                 batches and identifications
    (the jobs' artefacts -- diagnoses, tolerance bands, batches, identifications, gap sensitivities --
    are read and written through ``store.artifacts``, :mod:`app.storage.artifacts`, which owns their layout)

Rows (logs, vehicles, analyses, jobs, API keys) live in the database; a subclass provides the
connections (one per thread) and the :class:`~app.storage.dialect.Dialect`. The queries are
written once: writes run in :meth:`SQLStore._tx` transactions, and a read-then-write that two
processes must not interleave (a vehicle's next version, a log's first upload) is serialised on a
key (:meth:`~app.storage.dialect.Dialect.serialise`). Several processes may share one store: on
PostgreSQL, on several machines too, as long as they see the same files directory.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import shutil
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from app.errors import ConflictError, InputError, NotFoundError, StorageError
from app.log_formats import sidecar_of
from app.storage.artifacts import Artifacts
from app.storage.dialect import Connection, Dialect
from app.storage.jobtable import JobTable, now
from app.storage.keys import KeyTable
from app.storage.records import AnalysisRecord, JobStatus, LogRecord, VehicleRecord
from app.tempfiles import TMP, owner_tag, sweep

VEHICLE_NAME_CHARS = set("abcdefghijklmnopqrstuvwxyz0123456789-_")
MAX_VEHICLE_NAME = 64


def check_vehicle_name(name: str) -> str:
    """``name`` if it can name a vehicle, else 400 ``invalid_vehicle_name``.

    A vehicle's name becomes a directory (``vehicles/<name>/``) and part of file names, so every
    route checks it before it writes anything: no separators, dots, NULs or upper case can reach a path.
    """
    if not name or len(name) > MAX_VEHICLE_NAME or not set(name) <= VEHICLE_NAME_CHARS:
        raise InputError(f"vehicle name {name[:80]!r}: use 1-{MAX_VEHICLE_NAME} of a-z, 0-9, '-' and '_'",
                         code="invalid_vehicle_name")
    return name


def file_sha256(*paths: Path) -> str:
    h = hashlib.sha256()
    for p in paths:
        with p.open("rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


class SQLStore(JobTable, KeyTable):
    """Rows in a SQL database, content in files under ``root``; subclasses connect (``_conn``, ``close``)."""

    dialect: Dialect

    def __init__(self, root: Path) -> None:
        self.root = Path(root).resolve()
        try:
            for sub in (TMP, "logs", "vehicles", "analyses", "jobs"):
                (self.root / sub).mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StorageError(f"cannot create the data directory {self.root.name!r}: {exc.strerror}") from exc
        self.artifacts = Artifacts(self.root)
        self._local = threading.local()
        self._all: list[Any] = []  # every thread's connection, closed by close()
        self._lock = threading.Lock()

    @property
    def url(self) -> str:
        """Where to open this store again (``app.storage.url.open_store``), e.g. from a job worker."""
        raise NotImplementedError

    # -- connections: one per thread, made by the backend --------------------------------
    def _connect(self) -> Any:
        """A new connection in autocommit mode taking ``?`` placeholders."""
        raise NotImplementedError

    def _usable(self, conn: Any) -> bool:
        """False when ``conn`` can no longer be used (e.g. its server restarted): the thread gets a new one."""
        return True

    def _conn(self) -> Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None or not self._usable(conn):
            conn = self._connect()
            self._local.conn = conn
            with self._lock:
                self._all = [c for c in self._all if self._usable(c)]
                self._all.append(conn)
        return conn

    def close(self) -> None:
        with self._lock:
            for c in self._all:
                with contextlib.suppress(Exception):
                    c.close()
            self._all.clear()
        self._local = threading.local()

    @contextlib.contextmanager
    def _tx(self) -> Iterator[Connection]:
        db = self._conn()
        db.execute(self.dialect.begin)
        try:
            yield db
        except BaseException:
            with contextlib.suppress(Exception):  # a lost connection must not hide the cause
                db.execute("ROLLBACK")
            raise
        else:
            db.execute("COMMIT")

    # -- files -------------------------------------------------------------------------
    def temp_path(self, suffix: str = "") -> Path:
        """A new file name under ``<root>/tmp`` tagged with this process (:func:`app.tempfiles.owner_tag`)."""
        return self.root / TMP / f"{owner_tag()}{uuid.uuid4().hex}{suffix}"

    def clean_temp(self, older_than_s: float = 0.0) -> int:
        """Remove temporary files whose writer on this host is gone (a server or worker stopped mid-upload or
        mid-inflation) and those not written to for ``older_than_s`` seconds (an upload still being received
        by another server on the same files is younger than its idle limit); 0: every one."""
        return sweep(self.root / TMP, older_than_s)

    def analysis_dir(self, analysis_id: str) -> Path:
        return self.root / "analyses" / analysis_id

    # -- logs --------------------------------------------------------------------------
    def _log(self, row: Any) -> LogRecord:
        return LogRecord(
            id=row["id"], sha256=row["sha256"], filename=row["filename"], size_bytes=row["size_bytes"],
            format=row["format"], created_at=row["created_at"], path=self.root / row["path"], frames=row["frames"],
            duration_s=row["duration_s"], start_time=row["start_time"], issues=json.loads(row["issues"]),
            meta=json.loads(row["meta"]),
        )

    def add_log(self, temp: Path, *, sha256: str, filename: str, fmt: str, frames: int, duration_s: float,
                start_time: str | None, issues: list[dict[str, Any]], meta: dict[str, Any]) -> tuple[LogRecord, bool]:
        """Move ``temp`` into the store; returns ``(record, created)`` (False: same content already there)."""
        ext = "".join(Path(filename).suffixes[-2:]).lower()[:12] or ".log"
        rel = f"logs/{sha256}{ext}"
        with self._tx() as db:
            self.dialect.serialise(db, f"log {sha256}")  # one of two uploads of the same bytes inserts
            row = db.execute("SELECT * FROM logs WHERE sha256 = ?", (sha256,)).fetchone()
            if row is not None:
                temp.unlink(missing_ok=True)
                return self._log(row), False
            os.replace(temp, self.root / rel)
            db.execute(
                "INSERT INTO logs (id, sha256, filename, size_bytes, format, created_at, path, frames, duration_s,"
                " start_time, issues, meta) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)",
                (f"log_{sha256[:16]}", sha256, filename, (self.root / rel).stat().st_size, fmt, now(), rel, frames,
                 duration_s, start_time, json.dumps(issues), json.dumps(meta)),
            )
            row = db.execute("SELECT * FROM logs WHERE sha256 = ?", (sha256,)).fetchone()
        return self._log(row), True

    def find_log_by_hash(self, sha256: str) -> LogRecord | None:
        row = self._conn().execute("SELECT * FROM logs WHERE sha256 = ?", (sha256,)).fetchone()
        return self._log(row) if row else None

    def get_log(self, log_id: str) -> LogRecord:
        row = self._conn().execute("SELECT * FROM logs WHERE id = ?", (log_id,)).fetchone()
        if row is None:
            raise NotFoundError(f"log {log_id!r} not found")
        return self._log(row)

    def list_logs(self, limit: int = 100, offset: int = 0) -> list[LogRecord]:
        rows = self._conn().execute("SELECT * FROM logs ORDER BY created_at DESC LIMIT ? OFFSET ?", (limit, offset))
        return [self._log(r) for r in rows]

    def delete_log(self, log_id: str) -> list[str]:
        """Delete a log and its finished analyses; returns the ids of the analyses deleted with it."""
        log = self.get_log(log_id)
        with self._tx() as db:
            self.dialect.serialise(db, f"analyses of {log_id}")  # no analysis is added meanwhile
            busy = db.execute(
                "SELECT a.id FROM analyses a JOIN jobs j ON j.id = a.job_id WHERE a.log_id = ? AND j.status IN "
                "('queued', 'running')", (log_id,)).fetchone()
            if busy is not None:
                raise ConflictError(f"log {log_id} is in use by analysis {busy['id']} that has not finished",
                                    code="log_in_use")
            ids = [r["id"] for r in db.execute("SELECT id FROM analyses WHERE log_id = ?", (log_id,))]
            db.execute("DELETE FROM analyses WHERE log_id = ?", (log_id,))
            db.execute("DELETE FROM logs WHERE id = ?", (log_id,))
        for aid in ids:
            shutil.rmtree(self.analysis_dir(aid), ignore_errors=True)
        log.path.unlink(missing_ok=True)
        sidecar_of(log.path).unlink(missing_ok=True)  # its format description, when it came with one
        return ids

    # -- vehicles ----------------------------------------------------------------------
    def _vehicle(self, row: Any) -> VehicleRecord:
        return VehicleRecord(
            name=row["name"], version=row["version"], created_at=row["created_at"], sha256=row["sha256"],
            driveline_path=self.root / row["driveline_path"], database_path=self.root / row["database_path"],
            signal_map_path=self.root / row["signal_map_path"], summary=json.loads(row["summary"]),
        )

    def add_vehicle(self, name: str, *, driveline: Path, database: Path, signal_map: Path,
                    summary: dict[str, Any]) -> tuple[VehicleRecord, bool]:
        """Store a new version of vehicle ``name`` (files are copied); identical content returns the latest."""
        check_vehicle_name(name)
        digest = file_sha256(driveline, database, signal_map)
        with self._tx() as db:
            self.dialect.serialise(db, f"vehicle {name}")  # two uploads never both take the next version
            last = db.execute("SELECT * FROM vehicles WHERE name = ? ORDER BY version DESC LIMIT 1",
                              (name,)).fetchone()
            if last is not None and last["sha256"] == digest:
                return self._vehicle(last), False
            version = (last["version"] + 1) if last is not None else 1
            rel = Path("vehicles") / name / f"v{version}"
            (self.root / rel).mkdir(parents=True, exist_ok=True)
            dbc_name = "database" + (database.suffix.lower() or ".dbc")
            for src, dst in ((driveline, "driveline.toml"), (database, dbc_name), (signal_map, "signals.map.toml")):
                shutil.copyfile(src, self.root / rel / dst)
            db.execute(
                "INSERT INTO vehicles (name, version, created_at, sha256, driveline_path, database_path,"
                " signal_map_path, summary) VALUES (?,?,?,?,?,?,?,?)",
                (name, version, now(), digest, str(rel / "driveline.toml"), str(rel / dbc_name),
                 str(rel / "signals.map.toml"), json.dumps(summary)),
            )
            row = db.execute("SELECT * FROM vehicles WHERE name = ? AND version = ?", (name, version)).fetchone()
        return self._vehicle(row), True

    def get_vehicle(self, name: str, version: int | None = None) -> VehicleRecord:
        db = self._conn()
        if version is None:
            row = db.execute("SELECT * FROM vehicles WHERE name = ? ORDER BY version DESC LIMIT 1", (name,)).fetchone()
        elif not 0 < version < 2**62:  # also keeps numbers SQLite cannot bind out of the query
            row = None
        else:
            row = db.execute("SELECT * FROM vehicles WHERE name = ? AND version = ?", (name, version)).fetchone()
        if row is None:
            which = f"{name!r}" if version is None else f"{name!r} version {version}"
            raise NotFoundError(f"vehicle {which} not found")
        return self._vehicle(row)

    def list_vehicles(self) -> list[VehicleRecord]:
        rows = self._conn().execute(
            "SELECT v.* FROM vehicles v JOIN (SELECT name, MAX(version) AS version FROM vehicles GROUP BY name) m"
            " ON m.name = v.name AND m.version = v.version ORDER BY v.name")
        return [self._vehicle(r) for r in rows]

    def vehicle_versions(self, name: str) -> list[VehicleRecord]:
        rows = list(self._conn().execute("SELECT * FROM vehicles WHERE name = ? ORDER BY version", (name,)))
        if not rows:
            raise NotFoundError(f"vehicle {name!r} not found")
        return [self._vehicle(r) for r in rows]

    # -- analyses ----------------------------------------------------------------------
    _ANALYSIS_SQL = ("SELECT a.*, j.id AS j_id FROM analyses a JOIN jobs j ON j.id = a.job_id")

    def _analysis(self, row: Any) -> AnalysisRecord:
        return AnalysisRecord(
            id=row["id"], log_id=row["log_id"], vehicle_name=row["vehicle_name"],
            vehicle_version=row["vehicle_version"], options=json.loads(row["options"]), created_at=row["created_at"],
            job=self.get_job(row["job_id"]), result_dir=self.analysis_dir(row["id"]),
            summary=json.loads(row["summary"]),
        )

    def create_analysis(self, log_id: str, vehicle: VehicleRecord, options: dict[str, Any]) -> AnalysisRecord:
        self.get_log(log_id)
        analysis_id = f"an_{uuid.uuid4().hex[:16]}"
        with self._tx() as db:
            self.dialect.serialise(db, f"analyses of {log_id}")
            if db.execute("SELECT 1 FROM logs WHERE id = ?", (log_id,)).fetchone() is None:
                raise NotFoundError(f"log {log_id!r} not found")  # deleted since it was read above
            job_id = self._insert_job(db, "analysis", analysis_id)
            db.execute("INSERT INTO analyses (id, log_id, vehicle_name, vehicle_version, options, created_at, job_id,"
                       " summary) VALUES (?,?,?,?,?,?,?, '{}')",
                       (analysis_id, log_id, vehicle.name, vehicle.version, json.dumps(options), now(), job_id))
        return self.get_analysis(analysis_id)

    def get_analysis(self, analysis_id: str) -> AnalysisRecord:
        row = self._conn().execute(self._ANALYSIS_SQL + " WHERE a.id = ?", (analysis_id,)).fetchone()
        if row is None:
            raise NotFoundError(f"analysis {analysis_id!r} not found")
        return self._analysis(row)

    def list_analyses(self, log_id: str | None = None, limit: int = 100, offset: int = 0) -> list[AnalysisRecord]:
        where, args = ("WHERE a.log_id = ?", (log_id,)) if log_id else ("", ())
        rows = self._conn().execute(f"{self._ANALYSIS_SQL} {where} ORDER BY a.created_at DESC LIMIT ? OFFSET ?",
                                    (*args, limit, offset)).fetchall()
        return [self._analysis(r) for r in rows]

    def set_analysis_summary(self, analysis_id: str, summary: dict[str, Any]) -> None:
        with self._tx() as db:
            db.execute("UPDATE analyses SET summary = ? WHERE id = ?", (json.dumps(summary), analysis_id))

    def delete_analysis(self, analysis_id: str) -> None:
        rec = self.get_analysis(analysis_id)
        if rec.job.status in (JobStatus.QUEUED, JobStatus.RUNNING):
            raise ConflictError(f"analysis {analysis_id} is {rec.job.status.value}; delete it when it has finished",
                                code="analysis_busy")
        with self._tx() as db:
            db.execute("DELETE FROM analyses WHERE id = ?", (analysis_id,))
            db.execute("DELETE FROM jobs WHERE id = ?", (rec.job.id,))
        shutil.rmtree(rec.result_dir, ignore_errors=True)
