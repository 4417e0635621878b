"""The shared store: PostgreSQL for rows, a files directory every process sees for content.

``lashscope serve --store postgresql://user@host:5432/lashscope`` lets several API processes (and
their job workers), on one machine or several, share one database; the files (logs, vehicles,
results) live in ``?files=DIR`` of the URL or the data directory, which they must share too (a
network file system when they run on several machines). The queries are those of the SQLite store
(:mod:`app.storage.sqlstore`); :mod:`app.storage.dialect` holds what differs.

The driver is psycopg 3 (the ``postgres`` extra, ``pip install 'lashscope[postgres]'``). Every
thread gets its own connection in autocommit mode, transactions are explicit ``BEGIN``/``COMMIT``
(:meth:`SQLStore._tx`), and a connection found broken (the server restarted) is replaced at the
next use. A server with the default ``max_connections = 100`` serves about two API processes at
their default thread counts; raise it for more.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any
from urllib.parse import parse_qsl, quote, urlencode, urlsplit, urlunsplit

from app.errors import InputError, StorageError
from app.storage.dialect import POSTGRESQL
from app.storage.migrations import upgrade
from app.storage.sqlstore import SQLStore


class PgRow:
    """A result row read by column name (``row["id"]``) or position (``row[0]``), like ``sqlite3.Row``."""

    __slots__ = ("_index", "_values")

    def __init__(self, values: Sequence[Any], index: dict[str, int]) -> None:
        self._values, self._index = values, index

    def __getitem__(self, key: str | int) -> Any:
        return self._values[self._index[key] if isinstance(key, str) else key]

    def keys(self) -> list[str]:
        return list(self._index)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)


def _row_factory(cursor: Any) -> Any:
    index = {col.name: i for i, col in enumerate(cursor.description or ())}
    return lambda values: PgRow(values, index)


@lru_cache(maxsize=512)
def _placeholders(sql: str) -> str:
    """The store's ``?`` placeholders as psycopg's ``%s`` (a literal ``%`` doubled)."""
    return sql.replace("%", "%%").replace("?", "%s")


def _text(value: Any) -> Any:
    """PostgreSQL text cannot hold NUL (SQLite can): a client's id or name with one is looked up as U+FFFD, which
    no stored id has, so it is not found rather than a driver error; a message written with one keeps U+FFFD."""
    return value.replace("\x00", "\ufffd") if isinstance(value, str) and "\x00" in value else value


class PgConnection:
    """A psycopg connection that takes the store's SQL (``?`` placeholders) and yields :class:`PgRow` rows."""

    def __init__(self, raw: Any) -> None:
        self.raw = raw

    def execute(self, sql: str, parameters: Sequence[Any] = (), /) -> Any:
        if not parameters:
            return self.raw.execute(sql)
        return self.raw.execute(_placeholders(sql), tuple(_text(p) for p in parameters))

    @property
    def usable(self) -> bool:
        return not (self.raw.closed or self.raw.broken)

    def close(self) -> None:
        self.raw.close()


def split_url(url: str) -> tuple[str, Path | None]:
    """``postgresql://...?files=DIR&sslmode=...`` -> (the libpq URL without ``files``, DIR or None)."""
    parts = urlsplit(url)
    query = parse_qsl(parts.query, keep_blank_values=True)
    files = [v for k, v in query if k == "files"]
    rest = urlencode([(k, v) for k, v in query if k != "files"])
    return urlunsplit((parts.scheme, parts.netloc, parts.path, rest, parts.fragment)), (
        Path(files[-1]) if files else None)


def redact(url: str) -> str:
    """``url`` with its password (if any) replaced by ``***``, for messages and logs."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    netloc = parts.netloc.replace(f":{parts.password}@", ":***@", 1)
    return urlunsplit((parts.scheme, netloc, parts.path, parts.query, parts.fragment))


class PostgresStore(SQLStore):
    """PostgreSQL at ``conninfo`` (a ``postgresql://`` URL) + files under ``root``; opening upgrades the schema."""

    dialect = POSTGRESQL

    def __init__(self, conninfo: str, root: Path, connect_timeout_s: float = 10.0) -> None:
        try:
            import psycopg  # lazy: optional extra
        except ImportError as exc:
            raise InputError("a postgresql:// store needs the psycopg driver: pip install 'lashscope[postgres]'",
                             code="unsupported_store") from exc
        self._psycopg = psycopg
        super().__init__(root)
        self.conninfo = conninfo
        self.connect_timeout_s = connect_timeout_s
        try:
            upgrade(self._conn(), POSTGRESQL)
        except BaseException:
            self.close()  # e.g. a schema newer than this program: no connection is left open
            raise

    @property
    def url(self) -> str:
        sep = "&" if urlsplit(self.conninfo).query else "?"
        return f"{self.conninfo}{sep}files={quote(str(self.root))}"

    def _connect(self) -> PgConnection:
        try:
            raw = self._psycopg.connect(self.conninfo, autocommit=True, row_factory=_row_factory,
                                        connect_timeout=max(1, round(self.connect_timeout_s)))
        except self._psycopg.Error as exc:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            raise StorageError(f"cannot reach the store's database {redact(self.conninfo)}: {first}",
                               code="store_unreachable") from exc
        return PgConnection(raw)

    def _usable(self, conn: PgConnection) -> bool:
        return conn.usable
