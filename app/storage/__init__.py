"""Persistence: the :class:`~app.storage.base.Store` interface and its embedded SQLite + files default."""

from app.storage.base import Store
from app.storage.records import AnalysisRecord, JobRecord, JobStatus, LogRecord, VehicleRecord
from app.storage.sqlite import SQLiteStore

__all__ = ["AnalysisRecord", "JobRecord", "JobStatus", "LogRecord", "SQLiteStore", "Store", "VehicleRecord"]
