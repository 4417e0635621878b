"""Open a store from a URL: the one place that chooses the backend.

``sqlite:///relative/path.sqlite3`` and ``sqlite:////absolute/path.sqlite3`` (the SQLAlchemy
spelling) name the database file; the store's files (logs, vehicles, results) live beside it
unless ``?files=DIR`` says where. A plain path (no scheme) is a data directory with the database
at ``<dir>/lashscope.sqlite3``, as ``--data-dir`` always meant. Other schemes are refused by name:
a server backend such as PostgreSQL plugs in here, behind the same :class:`~app.storage.base.Store`.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import parse_qs, unquote, urlsplit

from app.errors import InputError
from app.storage.sqlite import SQLiteStore


def open_store(url: str | Path) -> SQLiteStore:
    text = str(url)
    if "://" not in text:
        return SQLiteStore(Path(text))
    parts = urlsplit(text)
    if parts.scheme != "sqlite":
        raise InputError(f"store URL scheme {parts.scheme!r} is not supported (use sqlite:///path/to/db.sqlite3 "
                         "or a data directory)", code="unsupported_store")
    if parts.netloc:
        raise InputError(f"store URL {text!r}: a sqlite URL has no host; write sqlite:///relative.sqlite3 or "
                         "sqlite:////absolute.sqlite3", code="unsupported_store")
    raw = unquote(parts.path)
    database = Path(raw[1:] if raw.startswith("/") else raw)  # sqlite:///x -> x, sqlite:////x -> /x
    if not database.name:
        raise InputError(f"store URL {text!r} names no database file", code="unsupported_store")
    files = parse_qs(parts.query).get("files")
    return SQLiteStore(Path(files[0]) if files else database.parent, database=database)
