"""Schema versions of the store: read the version, apply the missing migrations in order.

One ordered list (:data:`app.storage.schema.MIGRATIONS`) serves both backends; the statements are
written for SQLite and widened for PostgreSQL by :meth:`~app.storage.dialect.Dialect.ddl`.

The version lives in a one-column table ``schema_version`` (one row per applied migration, with
when it was applied). A database without that table is either new (version 0) or was made by the
first release, whose schema is migration 1 itself -- written with ``IF NOT EXISTS`` -- so both
cases start from 0 and the first release's tables are kept with their rows. Each migration runs
in its own transaction that first takes the database's write lock (SQLite's ``BEGIN IMMEDIATE``;
on PostgreSQL a transaction-scoped advisory lock) and re-reads the version, so two processes
opening the same database at once (two API servers, a server and a job worker) apply each
migration once. A database newer than this program refuses to open instead of being written with
an old schema.
"""

from __future__ import annotations

import contextlib
from datetime import UTC, datetime

from app.errors import StorageError
from app.storage.dialect import SQLITE, Connection, Dialect
from app.storage.schema import MIGRATIONS

LATEST = MIGRATIONS[-1][0]
_TABLE = "CREATE TABLE IF NOT EXISTS schema_version (version INTEGER PRIMARY KEY, applied_at TEXT NOT NULL)"


def schema_version(db: Connection, dialect: Dialect = SQLITE) -> int:
    """The highest applied migration (0: none, e.g. a new database or one made by the first release)."""
    if not dialect.has_table(db, "schema_version"):
        return 0
    value = db.execute("SELECT MAX(version) FROM schema_version").fetchone()[0]
    return int(value or 0)


def _statements(sql: str) -> list[str]:
    return [s.strip() for s in sql.split(";") if s.strip()]


def upgrade(db: Connection, dialect: Dialect = SQLITE) -> list[int]:
    """Apply every migration above the database's version, in order; returns the versions applied.

    ``db`` must be in autocommit mode (``isolation_level=None`` for sqlite3): each migration is one
    explicit transaction, so a failure leaves the database at the last complete version.
    """
    found = schema_version(db, dialect)
    if found > LATEST:
        raise StorageError(f"the store's schema is version {found}, newer than this lashscope knows "
                           f"(up to {LATEST}); upgrade lashscope", code="schema_too_new")
    applied: list[int] = []
    for version, _what, sql in MIGRATIONS:
        if version <= found:
            continue
        db.execute(dialect.begin)
        try:
            dialect.serialise(db, "lashscope schema")
            db.execute(dialect.ddl(_TABLE))
            if schema_version(db, dialect) >= version:  # another process applied it meanwhile
                db.execute("COMMIT")
                continue
            for stmt in _statements(sql):
                db.execute(dialect.ddl(stmt))
            db.execute("INSERT INTO schema_version (version, applied_at) VALUES (?, ?)",
                       (version, datetime.now(UTC).isoformat(timespec="milliseconds")))
        except BaseException:
            with contextlib.suppress(Exception):  # a lost connection must not hide the cause
                db.execute("ROLLBACK")
            raise
        db.execute("COMMIT")
        applied.append(version)
    return applied
