"""Persistence: the :class:`~app.storage.base.Store` interface, its embedded SQLite + files default and
the shared PostgreSQL store (:mod:`app.storage.postgres`, opened through :func:`app.storage.url.open_store`)."""

from app.storage.base import Store
from app.storage.records import AnalysisRecord, JobRecord, JobStatus, LogRecord, VehicleRecord
from app.storage.sqlite import SQLiteStore

__all__ = ["AnalysisRecord", "JobRecord", "JobStatus", "LogRecord", "SQLiteStore", "Store", "VehicleRecord"]
