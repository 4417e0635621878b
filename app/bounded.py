"""One request's work in a process of its own, with a CPU-time and a memory limit.

Some work a request asks for cannot be bounded by a count decided before it starts: a text log read
with a regular expression the client wrote (one line can make Python's regex engine backtrack for
hours, holding the interpreter lock, so no other request would be answered), or a signal map
proposed from a stored log of any size. :func:`run_bounded` runs such a function in a spawned
child (no fork of the threaded server): the kernel stops it after ``cpu_s`` seconds of CPU
(``RLIMIT_CPU``), its address space is capped at ``memory_mb`` (``RLIMIT_AS``: a ``MemoryError``
inside), a wall-time deadline kills it if it stalls, and it dies with the server. The CPU time counts
from when the child has imported what it runs (about 1 s). The server's
thread only waits on a pipe. Past a limit the caller gets a typed
:class:`~app.errors.WorkLimitError` naming it; the child's own typed errors come back as they were
raised; temporary files the child left (killed mid-inflation) are swept.
"""

from __future__ import annotations

import contextlib
import importlib
import math
import multiprocessing
import os
import resource
import signal
import threading
import time
from pathlib import Path
from typing import Any

from app.errors import AppError, QueueFullError, WorkLimitError
from app.tempfiles import TMP, sweep, temp_dir_of
from app.worker import die_with_parent

_SPAWN = multiprocessing.get_context("spawn")
START_WALL_S = 30.0  # the same in wall time on a loaded machine
MAX_CHILDREN = 2  # at once per server: each may hold its memory limit
WAIT_S = 10.0  # a request waits this long for a free slot, then 429
_slots = threading.BoundedSemaphore(MAX_CHILDREN)


class _CpuLimit(BaseException):  # not an Exception: no handler in the work may swallow it
    """Raised in the child by its CPU timer."""


def _out_of_cpu(signum: int, frame: Any) -> None:
    raise _CpuLimit


def _child(conn: Any, target: str, args: tuple[Any, ...], kwargs: dict[str, Any], root: str, parent: int,
           cpu_s: float, memory_mb: int) -> None:
    """In the child: limits, then ``target(*args)``; sends ``("ok", value)`` or the error as plain data."""
    die_with_parent(parent)
    limit = memory_mb * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    try:
        module, _, name = target.partition(":")
        fn = getattr(importlib.import_module(module), name)
        # cpu_s for the work itself, after the imports: a timer of the process' CPU time whose signal the regex
        # engine (and any Python code) notices within microseconds, and the kernel's limit a second later for
        # compiled code that never looks
        used = sum(resource.getrusage(resource.RUSAGE_SELF)[:2])
        cpu = math.ceil(used + cpu_s) + 1
        resource.setrlimit(resource.RLIMIT_CPU, (cpu, cpu + 1))  # SIGXCPU at the soft limit, SIGKILL at the hard
        signal.signal(signal.SIGPROF, _out_of_cpu)
        signal.setitimer(signal.ITIMER_PROF, cpu_s)
        with temp_dir_of(Path(root)):
            out: tuple[Any, ...] = ("ok", fn(*args, **kwargs))
        signal.setitimer(signal.ITIMER_PROF, 0)
    except _CpuLimit:
        out = ("cpu",)
    except AppError as exc:
        out = ("app_error", type(exc).__module__, type(exc).__qualname__, exc.detail, exc.code, exc.status)
    except MemoryError:
        out = ("memory",)
    except Exception as exc:  # a bug: the caller answers 500 with it
        out = ("bug", f"{type(exc).__name__}: {exc}")
    conn.send(out)
    conn.close()


def _rebuilt(module: str, qualname: str, detail: str, code: str, status: int) -> AppError:
    cls: Any = importlib.import_module(module)
    for part in qualname.split("."):
        cls = getattr(cls, part)
    if not (isinstance(cls, type) and issubclass(cls, AppError)):
        cls = AppError
    exc: AppError = cls.__new__(cls)
    AppError.__init__(exc, detail, code=code)
    if exc.status != status:
        exc.status = status
    return exc


def run_bounded(target: str, *args: Any, root: Path, what: str, setting: str, cpu_s: float, memory_mb: int,
                code: str = "work_limit", kwargs: dict[str, Any] | None = None) -> Any:
    """``target`` (``"module:function"``) called with ``args`` and ``kwargs`` in a child process, under the
    limits above.

    ``root``: the data directory (the child's temporary files go to its ``tmp/``); ``what`` names the work in
    messages and ``setting`` the setting of ``cpu_s``.
    Blocks the calling thread (call it from a worker thread of the server). Past the CPU time, the memory or
    the wall time (``4 x cpu_s`` plus start-up) raises :class:`WorkLimitError` with ``code``; while
    :data:`MAX_CHILDREN` run, a call waits up to :data:`WAIT_S`, then :class:`QueueFullError` (429 ``busy``)."""
    if not _slots.acquire(timeout=WAIT_S):
        raise QueueFullError(f"{what}: {MAX_CHILDREN} such requests are running; try again shortly", code="busy")
    try:
        return _run(target, args, kwargs or {}, root, what, setting, cpu_s, memory_mb, code)
    finally:
        _slots.release()


def _run(target: str, args: tuple[Any, ...], kwargs: dict[str, Any], root: Path, what: str, setting: str,
         cpu_s: float, memory_mb: int, code: str) -> Any:
    recv, send = _SPAWN.Pipe(duplex=False)
    proc = _SPAWN.Process(target=_child, daemon=True, name=f"lashscope-bounded-{target.rsplit(':', 1)[-1]}",
                          args=(send, target, args, kwargs, str(root), os.getpid(), cpu_s, memory_mb))
    proc.start()
    send.close()
    wall_s = 4 * cpu_s + START_WALL_S
    deadline = time.monotonic() + wall_s
    out: tuple[Any, ...] | None = None
    try:
        while out is None and time.monotonic() < deadline:
            if recv.poll(min(0.5, max(0.0, deadline - time.monotonic()))):
                with contextlib.suppress(EOFError, OSError):
                    out = recv.recv()
                if out is None:
                    break  # the child ended without an answer (killed at its CPU limit, or by the kernel)
    finally:
        recv.close()
        if out is None and proc.is_alive():
            proc.kill()
        proc.join()
        with contextlib.suppress(OSError):
            sweep(Path(root) / TMP, math.inf)  # what the child left if it was killed (it is gone now)
    if out is None or out[0] == "cpu":
        why = (f"more than {wall_s:g} s" if out is None and time.monotonic() >= deadline
               else f"more than {cpu_s:g} s of CPU ({setting})")
        raise WorkLimitError(f"{what} took {why} and was stopped", code=code)
    if out[0] == "ok":
        return out[1]
    if out[0] == "app_error":
        raise _rebuilt(*out[1:])
    if out[0] == "memory":
        raise WorkLimitError(f"{what} needed more than {memory_mb} MiB of memory and was stopped", code=code)
    raise RuntimeError(f"{what} failed: {out[1]}")
