"""Open a store from a URL: the one place that chooses the backend.

``sqlite:///relative/path.sqlite3`` and ``sqlite:////absolute/path.sqlite3`` (the SQLAlchemy
spelling) name the database file; the store's files (logs, vehicles, results) live beside it
unless ``?files=DIR`` says where. A plain path (no scheme) is a data directory with the database
at ``<dir>/lashscope.sqlite3``, as ``--data-dir`` always meant.

``postgresql://user[:password]@host[:port]/database`` (or ``postgres://``; any libpq URL parameter
such as ``?sslmode=require`` passes through) is a PostgreSQL server shared by several processes
(:mod:`app.storage.postgres`); its files live in ``?files=DIR``, else in ``files`` (the server's
data directory). Other schemes are refused by name.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

from app.errors import InputError
from app.storage.postgres import PostgresStore, redact, split_url
from app.storage.sqlite import SQLiteStore
from app.storage.sqlstore import SQLStore

POSTGRES_SCHEMES = ("postgresql", "postgres")


def open_store(url: str | Path, files: Path | None = None) -> SQLStore:
    """The store at ``url``; ``files`` is where a PostgreSQL store keeps its files when the URL says not."""
    text = str(url)
    if "://" not in text:
        return SQLiteStore(Path(text))
    parts = urlsplit(text)
    if parts.scheme in POSTGRES_SCHEMES:
        return _postgres(text, files)
    if parts.scheme != "sqlite":
        raise InputError(f"store URL scheme {parts.scheme!r} is not supported (use sqlite:///path/to/db.sqlite3, "
                         "postgresql://user@host/db or a data directory)", code="unsupported_store")
    if parts.netloc:
        raise InputError(f"store URL {text!r}: a sqlite URL has no host; write sqlite:///relative.sqlite3 or "
                         "sqlite:////absolute.sqlite3", code="unsupported_store")
    raw = unquote(parts.path)
    database = Path(raw[1:] if raw.startswith("/") else raw)  # sqlite:///x -> x, sqlite:////x -> /x
    if not database.name:
        raise InputError(f"store URL {text!r} names no database file", code="unsupported_store")
    found = parse_qs(parts.query).get("files")
    return SQLiteStore(Path(found[0]) if found else database.parent, database=database)


def _postgres(text: str, files: Path | None) -> SQLStore:
    conninfo, named = split_url(text)
    parts = urlsplit(conninfo)
    if not parts.path.strip("/"):
        raise InputError(f"store URL {redact(text)!r} names no database: write postgresql://user@host:port/dbname",
                         code="unsupported_store")
    root = named or files
    if root is None:
        raise InputError(f"store URL {redact(text)!r}: say where the files live (?files=DIR, or --data-dir)",
                         code="unsupported_store")
    return PostgresStore(conninfo, root)
