"""Temporary files: only under the data directory, named after the process that writes them, swept.

Uploads in progress, an inflated gzipped MF4 and any temporary file a library makes while the
server or a job worker runs go to ``<data>/tmp`` (:func:`temp_dir_of` sets Python's
``tempfile.tempdir`` there), never to the system's temporary folder, so they count against the
data volume the operator sized and are found again after a crash.

Every name starts with its writer's tag, ``<host>-<pid>-<start>-`` (:func:`owner_tag`): the host
(a hash of its name: several servers may share one files directory), the process id and the
process' start time (so a process id used again after a restart is not taken for the writer).
:func:`sweep` removes a file at once when its writer on this host is gone -- a server or worker
killed with ``kill -9`` mid-upload or mid-inflation -- and any file not written to for
``older_than_s`` seconds (a writer on another host cannot be asked).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import socket
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

TMP = "tmp"  # the data directory's folder for temporary files


def _host() -> str:
    return hashlib.sha256(socket.gethostname().encode()).hexdigest()[:8]


def _started(pid: int) -> str | None:
    """When process ``pid`` started (clock ticks since boot, from /proc); None when it does not exist.

    Without /proc (not Linux) a live process gives ``"0"``: its files are then swept by age only."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except FileNotFoundError:
        return None
    except OSError:
        return "0" if _alive(pid) else None
    fields = stat.rsplit(")", 1)[-1].split()
    return fields[19] if len(fields) > 19 else "0"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: alive
        return True
    return True


def owner_tag() -> str:
    """The prefix of every temporary file this process writes (``<host>-<pid>-<start>-``)."""
    pid = os.getpid()
    return f"{_host()}-{pid}-{_started(pid) or '0'}-"


def _writer_gone(name: str, host: str) -> bool:
    """Whether ``name`` carries a tag of this host whose process no longer runs."""
    parts = name.split("-", 3)
    if len(parts) < 4 or parts[0] != host or not parts[1].isdigit():
        return False
    started = _started(int(parts[1]))
    return started is None or (started != parts[2] and "0" not in (started, parts[2]))


def sweep(directory: Path, older_than_s: float = 0.0) -> int:
    """Remove temporary files (and folders) in ``directory`` whose writer is gone or that were not
    written to for ``older_than_s`` seconds (0: every one); returns how many were removed."""
    host, cutoff, removed = _host(), time.time() - older_than_s, 0
    for p in directory.iterdir():
        with contextlib.suppress(OSError):  # removed meanwhile by another sweep or its writer
            if older_than_s > 0 and not _writer_gone(p.name, host) and p.stat().st_mtime > cutoff:
                continue
            shutil.rmtree(p) if p.is_dir() and not p.is_symlink() else p.unlink()
            removed += 1
    return removed


@contextlib.contextmanager
def temp_dir_of(root: Path) -> Iterator[Path]:
    """Within this block every ``tempfile`` of the process goes to ``<root>/tmp``; the former folder after."""
    directory = Path(root) / TMP
    directory.mkdir(parents=True, exist_ok=True)
    before, tempfile.tempdir = tempfile.tempdir, str(directory)
    try:
        yield directory
    finally:
        tempfile.tempdir = before
