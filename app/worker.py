"""What every background worker process shares: it dies with the server that spawned it.

The job runner (:mod:`app.jobs`) spawns one process per job. Without this, ``kill -9`` of the server
would orphan a running worker; the restarted server would then run the same job again beside it,
outside any time limit.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal

_PR_SET_PDEATHSIG = 1  # linux/prctl.h


def die_with_parent(parent: int) -> None:
    """Have the kernel SIGKILL this process when ``parent`` dies (Linux); exit now if it already has."""
    with contextlib.suppress(OSError, AttributeError):  # not Linux: callers also check os.getppid() at progress reports
        ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:  # the server died before the line above took effect
        os._exit(1)
