"""What differs between the SQL backends of the store, in one place: SQLite and PostgreSQL.

The store's queries are written once, in the SQL both accept (``?`` placeholders, ``ON CONFLICT
DO NOTHING``, ``RETURNING``); a :class:`Dialect` supplies the few pieces that differ:

- how a writing transaction starts: SQLite's ``BEGIN IMMEDIATE`` takes the one database write lock
  at once, so writers serialise; PostgreSQL's ``BEGIN`` locks only rows, so a read-then-write that
  must not interleave (the next version of a vehicle, a migration) takes a transaction-scoped
  advisory lock on a key (:meth:`Dialect.serialise`);
- rows a transaction reads in order to change them are locked on PostgreSQL with
  ``FOR UPDATE SKIP LOCKED`` (:attr:`Dialect.lock_rows`), so two processes never both act on one;
- column types in the schema: SQLite's ``REAL`` is a double, PostgreSQL's a 4-byte float (which
  would round an epoch-second lease to minutes), and ``INTEGER`` is 4 bytes there (a log of more
  than 2 GiB would not fit): :meth:`Dialect.ddl` widens both for PostgreSQL;
- whether a table exists (``sqlite_master`` against ``to_regclass``).
"""

from __future__ import annotations

import re
import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, Protocol


class Cursor(Protocol):
    """What the store uses of a DB-API cursor; rows read by column name and by position."""

    @property
    def rowcount(self) -> int: ...
    def fetchone(self) -> Any: ...
    def fetchall(self) -> list[Any]: ...
    def __iter__(self) -> Iterator[Any]: ...


class Connection(Protocol):
    """A connection in autocommit mode whose ``execute`` takes ``?`` placeholders (``sqlite3`` as is,
    PostgreSQL through :class:`app.storage.postgres.PgConnection`)."""

    def execute(self, sql: str, parameters: Sequence[Any] = ..., /) -> Any: ...


_WIDEN = (
    (re.compile(r"\bREAL\b"), "DOUBLE PRECISION"),
    (re.compile(r"\bINTEGER\b"), "BIGINT"),
)


@dataclass(frozen=True)
class Dialect:
    name: str  # "sqlite" | "postgresql"
    begin: str  # starts a writing transaction
    lock_rows: str  # appended to a SELECT of rows the same transaction is about to update

    def ddl(self, sql: str) -> str:
        """A schema statement written for SQLite, in this dialect's column types."""
        if self.name == "postgresql":
            for pattern, wide in _WIDEN:
                sql = pattern.sub(wide, sql)
        return sql

    def has_table(self, db: Connection, table: str) -> bool:
        if self.name == "postgresql":
            return db.execute("SELECT to_regclass(?) IS NOT NULL", (table,)).fetchone()[0] is True
        return db.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = ?",
                          (table,)).fetchone() is not None

    def serialise(self, db: Connection, key: str) -> None:
        """Inside a transaction: wait until no other transaction holds ``key``, then hold it until commit.

        A no-op on SQLite, whose ``BEGIN IMMEDIATE`` has serialised every writer already."""
        if self.name == "postgresql":
            db.execute("SELECT pg_advisory_xact_lock(hashtextextended(?, 0))", (key,))


SQLITE = Dialect("sqlite", begin="BEGIN IMMEDIATE", lock_rows="")
POSTGRESQL = Dialect("postgresql", begin="BEGIN", lock_rows=" FOR UPDATE SKIP LOCKED")


def database_errors() -> tuple[type[Exception], ...]:
    """The exceptions a backend's driver raises when the database itself fails (for ``/health``)."""
    errors: list[type[Exception]] = [sqlite3.Error]
    try:
        import psycopg  # lazy: optional extra
    except ImportError:
        pass
    else:
        errors.append(psycopg.Error)
    return tuple(errors)
