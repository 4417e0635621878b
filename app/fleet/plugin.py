"""The Dask worker plugin that readies a worker for analyses once, when it joins.

A fresh worker's first analysis costs ~10 s more than the next ones: importing cantools,
python-can, asammdf, pandas and the simulator (~6 s on a loaded 2-core machine) and loading the
numba kernels from the on-disk cache (~1.5 s; compiling them cold takes ~30 s). The plugin does
it in :meth:`setup`, which Dask runs on every worker present and on every worker that joins later,
so each worker pays it once and before its first task (the kernels are compiled once per worker
at most, and never when the cache directory is shared and warm).
"""

from __future__ import annotations

from typing import Any

from distributed.diagnostics.plugin import WorkerPlugin

from app.fleet.work import warm_worker


class WarmWorker(WorkerPlugin):
    name = "lashscope-warm"

    def setup(self, worker: Any) -> None:
        if getattr(worker, "lashscope_warm_s", None) is None:  # registered again by a later batch: warm already
            worker.lashscope_warm_s = warm_worker()  # seconds, for the curious (client.run can read it)
