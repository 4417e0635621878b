"""The embedded default store: SQLite (WAL) for rows, plain files for content.

Layout of the data directory (the files as in :mod:`app.storage.sqlstore`)::

    <data_dir>/lashscope.sqlite3          logs, vehicles, analyses, jobs, API keys
    <data_dir>/tmp/ logs/ vehicles/ analyses/ jobs/

Every thread gets its own connection; writes run in ``BEGIN IMMEDIATE`` transactions
with a busy timeout, so concurrent uploads and job progress updates serialise instead
of failing -- between threads and between processes on one machine. Jobs are held through
leases (:mod:`app.storage.jobtable`), API keys as hashes (:mod:`app.storage.keys`); the schema
is versioned and upgraded on open (:mod:`app.storage.migrations`). The database may live
elsewhere than the files (``database=``; :func:`app.storage.url.open_store` opens a store
from a URL). Processes on several machines share a store on PostgreSQL instead
(:mod:`app.storage.postgres`).
"""

from __future__ import annotations

import sqlite3
from pathlib import Path
from urllib.parse import quote

from app.errors import StorageError
from app.storage.dialect import SQLITE
from app.storage.migrations import upgrade
from app.storage.sqlstore import VEHICLE_NAME_CHARS, SQLStore, file_sha256

__all__ = ["VEHICLE_NAME_CHARS", "SQLiteStore", "file_sha256"]


class SQLiteStore(SQLStore):
    """SQLite + files under ``root``; safe to share between threads of one process and between processes.

    ``database`` is the SQLite file (default ``<root>/lashscope.sqlite3``); opening upgrades its
    schema to the latest version (:mod:`app.storage.migrations`).
    """

    dialect = SQLITE

    def __init__(self, root: Path, database: Path | None = None) -> None:
        super().__init__(root)
        self.database = Path(database).resolve() if database is not None else self.root / "lashscope.sqlite3"
        upgrade(self._conn())

    @property
    def url(self) -> str:
        files = "" if self.database.parent == self.root else f"?files={quote(str(self.root))}"
        return f"sqlite:///{self.database}{files}"

    def _connect(self) -> sqlite3.Connection:
        try:
            conn = sqlite3.connect(self.database, timeout=30.0, isolation_level=None, check_same_thread=False)
        except sqlite3.Error as exc:
            raise StorageError(f"cannot open the store's database {self.database.name}: {exc}") from exc
        conn.row_factory = sqlite3.Row
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute("PRAGMA synchronous=NORMAL")
        conn.execute("PRAGMA foreign_keys=ON")
        return conn
