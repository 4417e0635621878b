"""What a stored log is, read once: format, frames, span, start time, channels and the damage found.

The upload check of the service (``POST /logs``, in a bounded child process when the client sends a
text layout), the demo and the live sessions call :func:`inspect_log` on every log they keep. It
needs only the readers, so a child process that runs it imports neither the analysis nor the
simulator (``tests/ingest/test_cli_imports.py``).
"""

from __future__ import annotations

import time
from dataclasses import asdict
from pathlib import Path
from typing import Any

from app.errors import LogFormatError, WorkLimitError
from app.ingest.readers import open_log
from app.progress import Progress, no_progress


def inspect_log(path: Path, progress: Progress = no_progress, cpu_s: float | None = None) -> dict[str, Any]:
    """Read a whole log once (salvaging) to count frames and collect what was damaged.

    Raises the reader's typed errors (UnsupportedFormatError, LogFormatError) when nothing
    usable is there, and :class:`~app.errors.WorkLimitError` (``validation_limit``) once reading
    has taken more than ``cpu_s`` seconds of this thread's CPU (checked after each block read from the
    log, so a log of damaged lines that never fills a chunk is stopped too).
    """
    frames = 0
    t_first: int | None = None
    t_last = 0
    started = time.thread_time()

    def check() -> None:
        if cpu_s is not None and time.thread_time() - started > cpu_s:
            raise WorkLimitError(f"{path.name}: reading it took more than {cpu_s:g} s of CPU "
                                 f"(LASHSCOPE_VALIDATE_CPU_S) and {frames} frames were read by then; "
                                 "split the log or raise the limit", code="validation_limit")

    with open_log(path) as reader:
        reader.limit_work(check)
        for chunk in reader.chunks():
            check()
            if len(chunk):
                frames += len(chunk)
                t_first = int(chunk.t_ns[0]) if t_first is None else min(t_first, int(chunk.t_ns[0]))
                t_last = max(t_last, int(chunk.t_ns.max()))
        meta, report = reader.meta, reader.report
    if frames == 0:
        raise LogFormatError(f"{path.name}: no CAN frames could be read ({len(report.issues)} problems found)")
    return {
        "format": meta.format, "frames": frames,
        "duration_s": (t_last - (t_first or 0)) / 1e9,
        "start_time": meta.start_time.isoformat() if meta.start_time else None,
        "start_clock": meta.start_clock,
        "issues": [asdict(i) for i in report.issues],
        "channels": {str(k): v for k, v in meta.channels.items()},
    }
