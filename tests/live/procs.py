"""The ``lashscope`` command in a child process, stopped with a signal once it is ready (CLI tests)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def lashscope(*args: str) -> list[str]:
    return [sys.executable, "-m", "app", *args]


def signal_when_ready(args: list[str], ready: Callable[[], bool], sig: signal.Signals, *,
                      ready_within_s: float = 20.0, exit_within_s: float = 10.0,
                      before_signal: Callable[[], None] | None = None) -> tuple[int, str, str]:
    """Run ``lashscope *args``, wait until ``ready()`` (at most ``ready_within_s``), call
    ``before_signal`` if given, send ``sig`` and return ``(returncode, stdout, stderr)``.

    The child never outlives the call: it is killed if it has not exited by then.
    """
    proc = subprocess.Popen(lashscope(*args), cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + ready_within_s
        while not ready() and time.monotonic() < deadline:
            time.sleep(0.05)
        if before_signal is not None:
            before_signal()
        os.kill(proc.pid, sig)
        out, err = proc.communicate(timeout=exit_within_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    return proc.returncode, out, err
