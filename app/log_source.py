"""Where a log comes from: a local path, a caller's binary file object, or an fsspec URL.

The readers (:func:`app.ingest.readers.open_log`) take a path or a binary file object. A
fleet's logs often live elsewhere (``s3://``, ``gcs://``, ``https://``, ``memory://``): when
:mod:`fsspec` is installed (it comes with the ``[fleet]`` extra, through dask) a string with a
``scheme://`` prefix is opened through it and handed to the readers as a file object. Plain
paths never touch fsspec.

:func:`content_hash` names a log by its bytes (SHA-256), which is how the batch recognises a
log it has already analysed, whatever its name or location.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

from app.errors import InputError, LogNotFoundError, StorageError

LogSource = str | os.PathLike[str] | BinaryIO
_URL = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*://")
HASH_BLOCK = 1 << 20


def is_url(source: object) -> bool:
    """True for a ``scheme://...`` string other than ``file://``."""
    return isinstance(source, str) and bool(_URL.match(source)) and not source.startswith("file://")


def source_name(source: LogSource) -> str:
    """The name to show for a log: the file name of a path or URL, the ``name`` of a file object."""
    if isinstance(source, str | os.PathLike):
        text = os.fspath(source)
        return text.rstrip("/").rsplit("/", 1)[-1] or text
    name = getattr(source, "name", None)
    return Path(name).name if isinstance(name, str) else "<stream>"


@contextlib.contextmanager
def opened(source: LogSource) -> Iterator[str | os.PathLike[str] | BinaryIO]:
    """``source`` as the readers take it: paths and file objects as they are, URLs opened with fsspec.

    Raises InputError when a URL is given but fsspec is not installed, LogNotFoundError when the
    URL names nothing, StorageError when it cannot be opened otherwise.
    """
    if isinstance(source, str) and source.startswith("file://"):
        yield source[len("file://"):]
        return
    if not is_url(source):
        yield source
        return
    assert isinstance(source, str)
    try:
        import fsspec  # lazy: optional extra, only for URLs
    except ImportError as exc:
        raise InputError(f"{source}: reading logs from URLs needs fsspec (pip install 'lashscope[fleet]')") from exc
    try:
        handle = fsspec.open(source, "rb").open()
    except FileNotFoundError as exc:
        raise LogNotFoundError(f"{source}: no such log") from exc
    except (OSError, ValueError, ImportError) as exc:  # unknown protocol, missing backend, connection refused
        raise StorageError(f"{source}: cannot open ({exc})") from exc
    try:
        yield handle
    finally:
        handle.close()


def content_hash(source: LogSource) -> str:
    """SHA-256 (hex) of a log's bytes, read in 1 MiB blocks (a file object is read from its position
    to the end and rewound when it can seek)."""
    digest = hashlib.sha256()
    with opened(source) as src:
        if isinstance(src, str | os.PathLike):
            try:
                with open(src, "rb") as fh:
                    _feed(digest, fh)
            except FileNotFoundError as exc:
                raise LogNotFoundError(f"{source_name(source)}: no such log") from exc
            except OSError as exc:
                raise StorageError(f"{source_name(source)}: cannot read ({exc.strerror or exc})") from exc
        else:
            start = src.tell() if src.seekable() else None
            _feed(digest, src)
            if start is not None:
                src.seek(start)
    return digest.hexdigest()


def _feed(digest: hashlib._Hash, fh: BinaryIO) -> None:
    while block := fh.read(HASH_BLOCK):
        digest.update(block)
