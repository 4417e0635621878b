"""Parsed CAN databases kept per process, keyed by the file's content hash.

Parsing a production DBC with cantools (plus the tolerant repairs of :mod:`app.ingest.database`)
takes 0.1-2 s; a batch worker analysing hundreds of logs of one vehicle would pay it for every
log. :func:`cached_database` parses each distinct content once per process and then hands out
the same :class:`~app.ingest.database.LoadedDatabase`:

- the key is the SHA-256 of the file's bytes (plus the ``tolerant`` flag), so an edited DBC at
  the same path is parsed again, and the same DBC under two names is parsed once;
- at most ``MAX_ENTRIES`` databases are kept, least recently used dropped first (a production
  DBC parses to a few MB of Python objects);
- the hash costs one read of the file (~1 ms per MB), far below a parse.

The returned database is shared: callers must treat it as read-only (the pipeline does).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass
from pathlib import Path

from app.errors import DatabaseError
from app.ingest.database import LoadedDatabase, load_database

MAX_ENTRIES = 8


@dataclass
class CacheStats:
    """Counters of this process' cache (for tests and the batch report)."""

    hits: int = 0
    misses: int = 0


_lock = threading.Lock()
_entries: OrderedDict[tuple[str, bool], LoadedDatabase] = OrderedDict()
stats = CacheStats()


def content_key(path: str | Path) -> str:
    """SHA-256 (hex) of the file at ``path``; DatabaseError when it cannot be read."""
    src = Path(path)
    try:
        return hashlib.sha256(src.read_bytes()).hexdigest()
    except OSError as exc:
        raise DatabaseError(f"{src}: cannot read database file ({exc.strerror or exc})") from exc


def cached_database(path: str | Path, *, tolerant: bool = True) -> LoadedDatabase:
    """:func:`~app.ingest.database.load_database` once per distinct content in this process.

    Raises what ``load_database`` raises; a failed parse is not cached (the next call retries).
    """
    key = (content_key(path), tolerant)
    with _lock:
        hit = _entries.get(key)
        if hit is not None:
            _entries.move_to_end(key)
            stats.hits += 1
            return hit
    loaded = load_database(path, tolerant=tolerant)  # parse outside the lock: other keys stay served
    with _lock:
        stats.misses += 1
        _entries[key] = loaded
        _entries.move_to_end(key)
        while len(_entries) > MAX_ENTRIES:
            _entries.popitem(last=False)
    return loaded


def clear() -> None:
    """Forget every cached database and reset the counters."""
    with _lock:
        _entries.clear()
        stats.hits = stats.misses = 0
