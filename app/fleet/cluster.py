"""The Dask side of the batch: a local cluster, or an existing scheduler, behind one context manager.

- No scheduler given: a :class:`distributed.LocalCluster` of ``workers`` processes with one
  thread each (the analysis is CPU-bound numpy/numba; threads would share the GIL-held parts),
  bound to 127.0.0.1 (its HTTP status port on a free loopback port, so clusters never collide).
- ``scheduler`` given (``tcp://host:8786``): connect within ``timeout_s``; an unreachable
  address raises :class:`SchedulerUnreachableError` (code ``scheduler_unreachable``), one line,
  never a hang.

Dask is optional (``pip install 'lashscope[fleet]'``); without it the batch says so, or runs
in-process with ``--workers 0``.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from typing import Any

from app.errors import AppError, InputError

# A worker runs its task in one thread and its event loop in another; every wake-up of the loop
# (by default a 20 ms tick, a 100 ms memory check, a 500 ms system sample) makes the task thread
# hand over the interpreter lock, and on a machine whose cores are busy with other work the loop
# thread may wait for a core while the task waits for the lock. Fewer wake-ups, same function.
# Measured on one worker (bench/batch.py, loaded 2-core machine), two defaults cost more still:
# - the statistical profiler samples the task thread's stack every 10 ms: an idle worker burnt
#   0.024 CPU-s per second, and a busy one takes the interpreter lock from the task 100 times a
#   second (profiles only feed the dashboard, which the batch does not open);
# - MALLOC_TRIM_THRESHOLD_=65536 in the workers' environment (so that freed memory goes back to
#   the system at once) also fixes glibc's mmap threshold, so every numpy temporary above 128 KiB
#   is a fresh mmap whose pages the kernel zeroes again: the analysis took 13 % more CPU in a
#   worker than in the calling process (0.753 s against 0.668 s a log); without it, 0.6 % more.
#   The thread-count caps of the same setting are kept (one thread per worker process).
QUIET_WORKERS = {
    "distributed.admin.tick.interval": "500ms",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
    "distributed.worker.profile.enabled": False,
    "distributed.nanny.pre-spawn-environ": {"OMP_NUM_THREADS": 1, "MKL_NUM_THREADS": 1, "OPENBLAS_NUM_THREADS": 1},
}


class SchedulerUnreachableError(AppError, ConnectionError):
    """No Dask scheduler answered at the given address within the connect timeout."""

    code = "scheduler_unreachable"
    status = 503


class ClusterStartError(AppError, RuntimeError):
    """The local cluster's worker processes did not come up (out of memory, no free port)."""

    code = "cluster_start_failed"
    status = 503


def _distributed() -> Any:
    try:
        import distributed  # lazy: Dask is an optional extra
    except ImportError as exc:
        raise InputError("the batch needs Dask: pip install 'lashscope[fleet]' (or run in-process with "
                         "--workers 0)") from exc
    return distributed


def local_cluster(workers: int) -> Any:
    """A started ``LocalCluster`` of ``workers`` single-threaded processes on 127.0.0.1 (HTTP port: any free one)."""
    distributed = _distributed()
    if workers < 1:
        raise InputError(f"--workers {workers}: a local cluster needs at least 1 worker (0 runs in-process)")
    import dask  # lazy: Dask is an optional extra

    try:
        with dask.config.set(QUIET_WORKERS):  # the nannies hand this configuration to their workers
            return distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                            host="127.0.0.1", dashboard_address=":0",
                                            silence_logs=logging.CRITICAL)
    except (OSError, RuntimeError, TimeoutError) as exc:
        raise ClusterStartError(f"the local Dask cluster of {workers} workers did not start: {exc}") from exc


@contextlib.contextmanager
def dask_client(scheduler: str | None, workers: int, timeout_s: float = 10.0) -> Iterator[Any]:
    """A connected ``distributed.Client``; the local cluster (if one was started) stops on exit."""
    distributed = _distributed()
    if scheduler:
        try:
            client = distributed.Client(scheduler, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise SchedulerUnreachableError(f"no Dask scheduler reachable at {scheduler} within {timeout_s:g} s "
                                            f"({type(exc).__name__})") from exc
        try:
            yield client
        finally:
            client.close()
        return
    cluster = local_cluster(workers)
    try:
        client = distributed.Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()
