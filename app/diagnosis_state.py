"""Background diagnoses that survive a restart: state files, owners, one worker, resume or fail.

A diagnosis (and a validation of one) runs one at a time, each in its own spawned worker process
with a wall-time limit (:class:`Worker`), and its state lives in a JSON file next to its results
(``status.json`` / ``validation.json``) that the worker writes its progress to. Why a process: the
fitting holds the GIL for long stretches, so in a thread of the server it would slow every request,
and a runaway fit could never be stopped; a process is killed after ``timeout_s`` and the work
fails with code ``timeout``. The worker dies with the server (``PR_SET_PDEATHSIG`` on Linux, and a
parent check at every progress report), so a killed server leaves no orphan fitting on. Queued and running work
records its *owner*: process id, the process' start time (Linux ``/proc``) and a token drawn when
this module is imported -- so a restarted server with the same pid (pid 1 in a container) is still
a different owner. With that, work cut off by a stop or a crash is recognisable:

- :func:`recover` (at startup) takes every queued or running piece whose owner is gone and either
  resumes it -- the diagnosis is deterministic, so the re-run gives the same report -- or, after
  :data:`MAX_ATTEMPTS` runs, marks it failed with the reason :data:`INTERRUPTED`, so work that
  brings the server down cannot do so forever. A crash or kill while running counts an attempt;
  work still queued, or stopped cleanly, does not. A claim file per dead owner (created
  exclusively) makes sure only one process resumes a piece when several start on one data
  directory;
- :meth:`Worker.close` (at shutdown) stops the running work -- it kills the worker process, or, with
  ``in_process=True``, asks the work to stop at its next progress report (:class:`Stopping`) -- and
  puts it back to ``queued``; queued work stays queued;
- :func:`state` marks work failed with the same reason when it is read while its owner is dead
  (another process on the same data directory crashed).
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import secrets
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from multiprocessing.process import BaseProcess
from pathlib import Path
from typing import Any

from app.errors import AppError
from app.worker import die_with_parent
from sim.errors import SimError

log = logging.getLogger("lashscope.diagnoses")

MAX_ATTEMPTS = 2  # runs of one piece of work (first + resumed) before an interruption fails it
INTERRUPTED = "interrupted by server restart"
ACTIVE = ("queued", "running")
_TOKEN = secrets.token_hex(8)
_FILE_LOCK = threading.Lock()
_SPAWN = multiprocessing.get_context("spawn")  # no fork of a threaded server; the child imports afresh

Check = Callable[[], None]
#: A piece of work: called with a ``check`` to call at every progress report. For a worker process it must
#: pickle (a module-level function or a :func:`functools.partial` of one), as it is sent to a spawned child.
Work = Callable[[Check], None]


class Stopping(Exception):
    """Raised from a progress report when the server stops: the work goes back to the queue."""


def write_json(path: Path, doc: dict[str, Any]) -> None:
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(doc, indent=1, allow_nan=False, default=str), encoding="utf-8")
    tmp.replace(path)


def update(path: Path, **kw: Any) -> dict[str, Any]:
    """Merge ``kw`` into a state file (atomic replace, stamped ``updated_at``); returns the new content."""
    with _FILE_LOCK:
        doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
        doc.update(kw, updated_at=time.time())
        write_json(path, doc)
    return doc


def _started(pid: int) -> int | None:
    """Start time of process ``pid`` in clock ticks since boot (Linux ``/proc/<pid>/stat`` field 22), or None."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii")
    except OSError:
        return None
    fields = stat.rsplit(")", 1)[-1].split()  # the name may hold spaces; fields after it start at 3
    return int(fields[19]) if len(fields) > 19 else None


def owner() -> dict[str, Any]:
    """This process as the owner of a piece of work."""
    return {"pid": os.getpid(), "started": _started(os.getpid()), "token": _TOKEN}


def owner_alive(who: Any) -> bool:
    """Whether the process that queued or runs a piece of work still exists."""
    if not isinstance(who, dict) or not isinstance(who.get("pid"), int):
        return False
    pid = who["pid"]
    if pid == os.getpid():
        return bool(who.get("token") == _TOKEN)
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass  # exists, another user's
    recorded = who.get("started")
    return recorded is None or _started(pid) in (None, recorded)


def interrupted(path: Path, attempts: int) -> dict[str, Any]:
    """Mark cut-off work failed in its file and return the new content."""
    return update(path, status="failed", owner=None,
                  error={"code": "interrupted", "detail": f"{INTERRUPTED} (attempt {attempts} of {MAX_ATTEMPTS})"})


def state(path: Path) -> dict[str, Any] | None:
    """A state file's content (None if absent); work whose owner died is marked failed first."""
    if not path.is_file():
        return None
    doc: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    if doc.get("status") in ACTIVE and doc.get("owner") and not owner_alive(doc["owner"]):
        doc = interrupted(path, int(doc.get("attempts", 1)))
    return doc


def run_guarded(path: Path, work: Work, check: Check) -> None:
    """Run ``work``; its failures and a stop end up in the state file, never in the server."""
    try:
        work(check)
    except Stopping:
        # the owner stays: once this process has exited, the next start sees it gone and resumes the work
        _requeue(path)
    except (AppError, SimError) as exc:
        update(path, status="failed", owner=None, error={"code": getattr(exc, "code", "error"), "detail": str(exc)})
    except MemoryError:
        update(path, status="failed", owner=None,
               error={"code": "out_of_memory", "detail": "the work ran out of memory"})
    except Exception as exc:  # a bug must fail the diagnosis, not the server
        log.exception("diagnosis work %s failed", path)
        update(path, status="failed", owner=None,
               error={"code": "internal_error", "detail": f"{type(exc).__name__}: {exc}"})


def _requeue(path: Path) -> None:
    update(path, status="queued", stage="stopped with the server; resumes at the next start")


def _child(path: str, work: Work, parent: int) -> None:
    """Entry point of a worker process: run one piece of work, writing its state to ``path``."""
    die_with_parent(parent)

    def check() -> None:
        if os.getppid() != parent:
            os._exit(1)  # the server is gone: the file stays "running" for a dead owner, the next start decides

    update(Path(path), worker_pid=os.getpid())  # for operators (and tests): which process to look at
    run_guarded(Path(path), work, check)


class Worker:
    """Runs diagnoses one at a time, each in a spawned process killed after ``timeout_s`` (seconds; None: no limit).

    ``in_process=True`` runs the work in the worker thread instead (no isolation, no time limit); the work
    then stops at its next ``check()`` once :meth:`close` is called.
    """

    def __init__(self, timeout_s: float | None = None, in_process: bool = False,
                 timeout_setting: str = "LASHSCOPE_DIAGNOSIS_TIMEOUT_S") -> None:
        self.pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="diagnosis")
        self.stopping = threading.Event()
        self.timeout_s = timeout_s
        self.in_process = in_process
        self.timeout_setting = timeout_setting
        self._procs: dict[Path, BaseProcess] = {}
        self._lock = threading.Lock()

    def submit(self, path: Path, work: Work) -> None:
        """Queue ``work`` whose state lives in ``path`` (this process becomes its owner)."""
        update(path, owner=owner())
        self.pool.submit(self._run, path, work)

    def check(self) -> None:
        """Progress check of in-process work: raises :class:`Stopping` once the server stops."""
        if self.stopping.is_set():
            raise Stopping

    def _run(self, path: Path, work: Work) -> None:
        if self.stopping.is_set():
            return  # picked up after the stop: it is still queued in its file
        if self.in_process:
            run_guarded(path, work, self.check)
            return
        proc = _SPAWN.Process(target=_child, args=(str(path), work, os.getpid()), daemon=True,
                              name=f"lashscope-diagnosis-{path.parent.name}")
        with self._lock:
            if self.stopping.is_set():
                return
            proc.start()
            self._procs[path] = proc
        try:
            proc.join(self.timeout_s)
            if proc.is_alive():
                proc.kill()
                proc.join()
                if not self.stopping.is_set():
                    update(path, status="failed", owner=None,
                           error={"code": "timeout", "detail": f"timed out after {self.timeout_s:g} s "
                                  f"({self.timeout_setting}); the worker was stopped"})
                    log.warning("diagnosis work %s timed out after %g s", path, self.timeout_s)
                return
        finally:
            with self._lock:
                self._procs.pop(path, None)
        doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
        if doc.get("status") in ACTIVE and not self.stopping.is_set():
            code = proc.exitcode
            reason = f"killed by signal {-code}" if code is not None and code < 0 else f"exit code {code}"
            update(path, status="failed", owner=None,
                   error={"code": "worker_died", "detail": f"the worker process ended without a result ({reason})"})

    def close(self) -> None:
        """Stop: running work is stopped and goes back to ``queued``; queued work stays queued in its files."""
        with self._lock:
            self.stopping.set()
            procs = dict(self._procs)
        for path, proc in procs.items():
            proc.kill()  # deterministic work restarts from the beginning, so nothing is lost by not waiting
            proc.join()
            doc = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
            if doc.get("status") in ACTIVE:
                _requeue(path)
        self.pool.shutdown(wait=False, cancel_futures=True)


def _claim(path: Path, previous: Any) -> bool:
    """Only one process resumes a piece of work left by ``previous`` (its dead owner): whoever creates the claim."""
    token = previous.get("token") if isinstance(previous, dict) else None
    try:
        fd = os.open(path.with_name(f"{path.stem}.claim-{token or 'none'}"), os.O_CREAT | os.O_EXCL | os.O_WRONLY)
    except FileExistsError:
        return False
    os.close(fd)
    return True


def recover(paths: list[tuple[str, Path, Callable[[], Work]]], worker: Worker) -> dict[str, list[str]]:
    """Resume or fail the cut-off work among ``paths`` (label, state file, builder of the work).

    Returns ``{"resumed": [labels], "failed": [labels]}``.
    """
    done: dict[str, list[str]] = {"resumed": [], "failed": []}
    for label, path, build in paths:
        if not path.is_file():
            continue
        doc = json.loads(path.read_text(encoding="utf-8"))
        if doc.get("status") not in ACTIVE or owner_alive(doc.get("owner")):
            continue
        attempts = int(doc.get("attempts", 1)) + (1 if doc.get("status") == "running" else 0)
        if not _claim(path, doc.get("owner")):
            continue
        if attempts > MAX_ATTEMPTS:
            interrupted(path, attempts - 1)
            done["failed"].append(label)
            continue
        try:
            work = build()
        except (AppError, SimError, KeyError, TypeError, ValueError, OSError) as exc:
            update(path, status="failed", owner=None,
                   error={"code": "interrupted", "detail": f"{INTERRUPTED}; it cannot be resumed: {exc}"})
            done["failed"].append(label)
            continue
        update(path, status="queued", attempts=attempts,
               stage=f"resumed after a server restart (attempt {attempts} of {MAX_ATTEMPTS})")
        worker.submit(path, work)
        done["resumed"].append(label)
    return done
