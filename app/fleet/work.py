"""What one batch task does with one log, wherever it runs (a Dask worker or the calling process).

:func:`analyse_log` decodes, analyses and (optionally) diagnoses one log and returns a plain,
picklable dict -- never raises for a problem with the log: a typed error becomes
``{"status": "failed", "code": ..., "message": ...}`` so one bad log cannot stop a batch, and the
error code crosses the process boundary as data. The caller (:mod:`app.fleet.batch`) writes the
results; the task touches no output, so a task re-run after a worker died is harmless.

The pipeline is called as :func:`app.pipeline.decode_log` + :func:`app.pipeline.analyze_signals`; the
batch writes its own event rows (the service's event-store hook runs only where the service calls it).

A Dask worker imports this module to unpickle the worker plugin (:mod:`app.fleet.plugin`) or its first
task, so everything an analysis imports is loaded then, once per worker, before any task is timed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.errors import AppError
from app.log_source import LogSource, source_name
from app.payload import result_payload
from app.pipeline import AnalysisOptions, analyze_signals, decode_log
from app.storage.results import json_safe
from sim import SimError, load_vehicle, simulate


@dataclass(frozen=True)
class BatchSpec:
    """Everything a task needs besides the log: the vehicle inputs (paths must be readable where the
    task runs: a shared file system on a real cluster), the analysis options, whether to diagnose."""

    inputs: Any  # app.pipeline.VehicleInputs
    options: dict[str, Any] = field(default_factory=dict)  # AnalysisOptions.to_dict()
    diagnose: bool = False


def _failure(exc: BaseException, name: str) -> dict[str, Any]:
    if isinstance(exc, AppError) or hasattr(exc, "code"):
        code, message = str(getattr(exc, "code", "error")), str(exc)
    elif isinstance(exc, MemoryError):
        code, message = "out_of_memory", f"{name}: the analysis ran out of memory"
    else:  # a bug: keep the batch going and say what it was
        code, message = "internal_error", f"{type(exc).__name__}: {exc}"
    return {"status": "failed", "code": code, "message": message}


def _diagnosis(signals: Any, spec: BatchSpec) -> dict[str, Any]:
    # lazy: the diagnosis library only for batches that diagnose
    from app.analysis.diagnosis import DiagnosisOptions, diagnose_signals

    model = spec.options.get("model", "multibody")
    result = diagnose_signals(signals, spec.inputs.vehicle, DiagnosisOptions(model=model))
    return {"status": result.decision.status, "top": list(result.decision.top)}


def analyse_log(source: LogSource, spec: BatchSpec) -> dict[str, Any]:
    """Analyse one log; ``{"status": "ok", "doc": {...}, "diagnosis": ..., "elapsed_s": ..., "cpu_s": ...}``
    or a failure (with the same two times, in seconds).

    ``doc`` holds the parts of the analysis document the event rows and the per-log record need
    (events, metrics, summary, tracking, ingest, notes), JSON-safe.
    """
    clock, cpu = time.perf_counter(), time.thread_time()
    name = source_name(source)
    try:
        signals, ingest = decode_log(source, spec.inputs.database, spec.inputs.signal_map)
        result = analyze_signals(signals, spec.inputs.vehicle, AnalysisOptions.from_dict(spec.options))
        full, _ = result_payload(result)
        full["ingest"] = ingest
        doc = {k: full[k] for k in ("summary", "events", "metrics", "tracking", "ingest", "notes")}
        diagnosis = None
        if spec.diagnose:
            try:
                diagnosis = _diagnosis(result.signals, spec)  # as checked: an inverted torque corrected
            except (AppError, SimError) as exc:  # an undiagnosable log keeps its analysis
                diagnosis = {"status": "failed", "top": [], "code": getattr(exc, "code", "error"),
                             "message": str(exc)}
        out: dict[str, Any] = {"status": "ok", "doc": json_safe(doc), "diagnosis": diagnosis}
    except Exception as exc:
        out = _failure(exc, name)
    out["elapsed_s"] = time.perf_counter() - clock
    out["cpu_s"] = time.thread_time() - cpu  # this thread's CPU: the analysis alone, whatever the machine's load
    return out


def warm_kernels() -> float:
    """Compile (or load from numba's on-disk cache) the simulator kernels in this process; seconds taken.

    The kernels are compiled with ``cache=True``: the first process ever pays ~30 s, every later
    one loads the cache in ~1.5 s. Called before the workers start, so parallel workers load a
    ready cache instead of each compiling the same kernels at once.
    """
    clock = time.perf_counter()
    vehicle = load_vehicle("paper")
    t = np.arange(0.0, 0.2, 0.001)
    torque = np.where(t > 0.05, 100.0, -30.0)
    for model in ("multibody", "two_inertia"):
        simulate(vehicle, t, torque, model=model, output_dt=0.001)
    return time.perf_counter() - clock


def warm_worker() -> float:
    """Load the kernels (:func:`warm_kernels`) in a worker; seconds taken. What an analysis imports was loaded
    with this module (see the module docstring)."""
    return warm_kernels()
