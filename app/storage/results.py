"""Result files of a finished job: one JSON document plus named float64 ``.npy`` arrays.

Written to a temporary folder and renamed into place, so a reader never sees half a result and
a crash leaves no partial result behind; nothing else in the directory is touched. Readers memory-map the
arrays and keep recently used results open (:class:`ResultCache`), so a dashboard read
touches only the pages it needs.
"""

from __future__ import annotations

import contextlib
import errno
import json
import math
import os
import shutil
import threading
import uuid
from collections import OrderedDict
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
import numpy.typing as npt

from app.errors import NotFoundError, StorageError, StorageFullError

DOC = "result.json"
T = TypeVar("T")
FULL_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT})
NEARLY_FULL_BYTES = 1 << 20  # a short write with less than this left on the volume is a full volume


def write_failure(exc: OSError, what: str, directory: Path) -> StorageError:
    """The typed error of a failed write into ``directory``: :class:`StorageFullError` (507) when the
    volume is full, else :class:`StorageError`; the message names ``what``, never a path.

    numpy writes arrays in C and reports a short write as ``OSError("N requested and M written")``
    without an errno, so a write failing without one counts as full when the volume has (next to)
    nothing left.
    """
    full = exc.errno in FULL_ERRNOS
    if exc.errno is None:
        with contextlib.suppress(OSError):
            full = shutil.disk_usage(directory).free < NEARLY_FULL_BYTES
    if full:
        return StorageFullError(f"cannot write {what}: the server's data volume is full")
    return StorageError(f"cannot write {what}: {exc.strerror or 'the write was cut short'}")


def json_safe(obj: Any) -> Any:
    """``obj`` with NaN/inf floats replaced by None and numpy scalars by Python numbers."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


def write_result(directory: Path, doc: Mapping[str, Any], arrays: Mapping[str, npt.NDArray[Any]]) -> None:
    """Write a result into ``directory`` without touching anything else there.

    The directory is shared: an analysis' diagnoses (``diagnoses/``) and tolerance bands live beside
    its result and may be written while the analysis still runs, so only ``arrays/`` and
    ``result.json`` are replaced. Both are built in a hidden temporary folder inside ``directory``;
    the arrays folder is swapped in first and the document last, so a reader (which looks for the
    document) never sees half a result and a crash leaves none.
    """
    tmp = directory / f".result-{uuid.uuid4().hex[:8]}.tmp"
    old = directory / f".arrays-{uuid.uuid4().hex[:8]}.old"
    try:
        (tmp / "arrays").mkdir(parents=True)
        for name, arr in arrays.items():
            np.save(tmp / "arrays" / f"{name}.npy", np.ascontiguousarray(arr, dtype=np.float64))
        (tmp / DOC).write_text(json.dumps(json_safe(dict(doc)), allow_nan=False), encoding="utf-8")
        with contextlib.suppress(FileNotFoundError):
            os.replace(directory / "arrays", old)
        os.replace(tmp / "arrays", directory / "arrays")
        os.replace(tmp / DOC, directory / DOC)
    except OSError as exc:
        raise write_failure(exc, f"results ({directory.name})", directory) from exc
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.rmtree(old, ignore_errors=True)


class ResultFiles:
    """A finished result directory: the document and memory-mapped arrays."""

    def __init__(self, directory: Path) -> None:
        self.directory = directory
        try:
            self.doc: dict[str, Any] = json.loads((directory / DOC).read_text(encoding="utf-8"))
        except FileNotFoundError as exc:
            raise NotFoundError(f"no results in {directory.name}") from exc
        self._arrays: dict[str, npt.NDArray[np.float64]] = {}
        self._derived: dict[object, object] = {}
        self._lock = threading.Lock()
        self._building: dict[object, threading.Lock] = {}

    def has(self, name: str) -> bool:
        return (self.directory / "arrays" / f"{name}.npy").exists()

    def array(self, name: str) -> npt.NDArray[np.float64]:
        with self._lock:
            arr = self._arrays.get(name)
            if arr is None:
                path = self.directory / "arrays" / f"{name}.npy"
                if not path.exists():
                    raise NotFoundError(f"result {self.directory.name} has no series {name!r}")
                arr = np.load(path, mmap_mode="r")
                self._arrays[name] = arr
            return arr


    def built(self, key: object) -> bool:
        """Whether :meth:`derived` has built ``key`` for these files."""
        with self._lock:
            return key in self._derived

    def derived(self, key: object, build: Callable[[], T]) -> T:
        """``build()`` once per key and keep it with these files (results never change once written)."""
        with self._lock:
            if key in self._derived:
                return self._derived[key]  # type: ignore[return-value]
            building = self._building.setdefault(key, threading.Lock())
        # concurrent first readers of one key wait for one build; other keys' readers do not wait (a build
        # of every channel after an analysis must not hold up the whole-log read on the event loop)
        with building:
            with self._lock:
                if key in self._derived:
                    return self._derived[key]  # type: ignore[return-value]
            value = build()
            with self._lock:
                self._derived[key] = value
                self._building.pop(key, None)
            return value


class ResultCache:
    """The most recently used :class:`ResultFiles`, keyed by directory."""

    def __init__(self, size: int = 32) -> None:
        self.size = size
        self._items: OrderedDict[Path, ResultFiles] = OrderedDict()
        self._lock = threading.Lock()

    def get(self, directory: Path) -> ResultFiles:
        with self._lock:
            hit = self._items.get(directory)
            if hit is not None:
                self._items.move_to_end(directory)
                return hit
        files = ResultFiles(directory)
        with self._lock:
            self._items[directory] = files
            while len(self._items) > max(self.size, 1):
                self._items.popitem(last=False)
        return files

    def peek(self, directory: Path) -> ResultFiles | None:
        """The open files of ``directory`` if kept, without opening them (or counting as a use)."""
        with self._lock:
            return self._items.get(directory)

    def forget(self, directory: Path) -> None:
        with self._lock:
            self._items.pop(directory, None)
