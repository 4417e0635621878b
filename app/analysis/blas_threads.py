"""One BLAS thread while an analysis runs: OpenBLAS's idle worker threads spin, and the fit's many small calls
(a dot product per pass, an SVD per trust-region step) wake them thousands of times.

numpy and scipy each load their own OpenBLAS, which starts one worker per core. After every call
large enough to be split, the workers busy-wait for the next one before they sleep; a diagnosis
makes thousands of such calls between simulator passes, so on a 2-core machine the workers burn
about as much CPU as the fit itself and take the cores the simulator threads need. The products
in a fit are small (a 40 000 x 8 Jacobian at most), so one thread costs them nothing.

:func:`single_blas_thread` sets every loaded OpenBLAS to one thread for the duration of a ``with``
block and restores the previous count when the last such block in the process ends. Where no
OpenBLAS is loaded (another BLAS, another platform) it does nothing.
"""

from __future__ import annotations

import ctypes
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

ENABLED = True  # False: leave the thread count alone (the benchmark's reference runs)
_PAIRS = (  # (set, get) symbol names: numpy/scipy wheels' 64-bit-integer builds first, then plain OpenBLAS
    ("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
    ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
    ("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
    ("openblas_set_num_threads", "openblas_get_num_threads"),
)
_Fn = Callable[..., Any]  # a ctypes foreign function
_LOCK = threading.Lock()
_DEPTH = 0
_SAVED: list[tuple[_Fn, int]] = []
_LIBS: dict[str, tuple[_Fn, _Fn] | None] = {}


def _loaded_openblas() -> list[tuple[_Fn, _Fn]]:
    """(set, get) functions of every OpenBLAS mapped into this process (Linux: ``/proc/self/maps``)."""
    try:
        maps = Path("/proc/self/maps").read_text(encoding="utf-8", errors="replace")
    except OSError:
        return []
    found = []
    for line in maps.splitlines():
        if "openblas" not in line.lower():
            continue
        path = line.rsplit(" ", 1)[-1]
        if "openblas" not in Path(path).name.lower() or ".so" not in path:
            continue
        if path not in _LIBS:
            _LIBS[path] = None
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for set_name, get_name in _PAIRS:
                if hasattr(lib, set_name) and hasattr(lib, get_name):
                    set_fn, get_fn = getattr(lib, set_name), getattr(lib, get_name)
                    set_fn.argtypes, set_fn.restype = [ctypes.c_int], None
                    get_fn.argtypes, get_fn.restype = [], ctypes.c_int
                    _LIBS[path] = (set_fn, get_fn)
                    break
        if (pair := _LIBS[path]) is not None and pair not in found:
            found.append(pair)
    return found


@contextmanager
def single_blas_thread() -> Iterator[None]:
    """Every loaded OpenBLAS on one thread inside the block (nested and concurrent blocks share one setting)."""
    global _DEPTH
    if not ENABLED:
        yield
        return
    with _LOCK:
        if _DEPTH == 0:
            _SAVED.clear()
            for set_fn, get_fn in _loaded_openblas():
                _SAVED.append((set_fn, int(get_fn())))
                set_fn(1)
        _DEPTH += 1
    try:
        yield
    finally:
        with _LOCK:
            _DEPTH -= 1
            if _DEPTH == 0:
                for set_fn, count in _SAVED:
                    set_fn(count)
                _SAVED.clear()
