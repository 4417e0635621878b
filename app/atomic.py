"""Atomic file writes: a reader sees the old file or the whole new one, never half of either.

The new content goes to a temporary name in the target's own directory (so the rename cannot cross
file systems), unique per write (``.<name>.<random>.tmp``: two writers of the same file never share
it), is flushed to the disk (``fsync``) and renamed over the target with ``os.replace`` (atomic on
POSIX and Windows). When writing fails the temporary file is removed and the target is untouched.

Every file the project rewrites in place goes through :func:`atomic_path` (or :func:`write_text`
for text): stored job artefacts, caches, event-store Parquet files, rating models, the demo log.
"""

from __future__ import annotations

import contextlib
import os
import uuid
from collections.abc import Iterator
from pathlib import Path


def temp_sibling(path: Path, suffix: str = "") -> Path:
    """A new, unique hidden name beside ``path`` (ending in ``suffix`` after ``.tmp``, for a writer that
    chooses the format by the name's ending)."""
    return path.with_name(f".{path.name}.{uuid.uuid4().hex}.tmp{suffix}")


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str], suffix: str = "") -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on a clean exit it is synced and renamed to ``path``.

    A writer that takes a file name (a BLF or Parquet writer) writes the yielded path. On an exception the
    temporary file is removed and the exception propagates; ``path`` keeps what it had.
    """
    target = Path(path)
    tmp = temp_sibling(target, suffix)
    try:
        yield tmp
        _fsync(tmp)
        os.replace(tmp, target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Replace ``path``'s content with ``text`` (UTF-8), atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
