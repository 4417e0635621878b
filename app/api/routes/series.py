"""Series reads for dashboards: aligned speed (whole log or one event) and decoded signals.

``max_points`` keeps at most that many rows, choosing in every bucket the rows with each
column's minimum and maximum so shuffle peaks survive (``method=lttb``: largest-triangle-
three-buckets instead); ``t0``/``t1`` cut a time range first.
``format=csv`` (or ``Accept: text/csv``) returns CSV instead of JSON. Responses of finished
analyses never change, so they are cached by their query.
"""

from __future__ import annotations

import io
import json
import re
import threading
from collections import OrderedDict
from collections.abc import Callable
from typing import Annotated, Any, Literal

import numpy as np
import numpy.typing as npt
from fastapi import APIRouter, Query, Request, Response
from fastapi.concurrency import run_in_threadpool
from starlette.types import ASGIApp, Receive, Scope, Send

from app.analysis.downsample import BlockExtremes, Method, downsample
from app.api.deps import ResultsDep, StoreDep
from app.api.numbers import json_numbers
from app.api.routes.analyses import ON_DELETE, finished
from app.api.schemas import ERRORS, SeriesOut, SignalsOut
from app.errors import InputError, NotFoundError
from app.payload import SERIES_COLUMNS
from app.storage.base import Store
from app.storage.records import JobRecord
from app.storage.results import ResultCache, ResultFiles

router = APIRouter(prefix="/analyses", tags=["series"], responses=ERRORS)
F64 = npt.NDArray[np.float64]
SERIES_DOC: dict[int | str, dict[str, Any]] = {200: {"model": SeriesOut, "content": {"text/csv": {}}}}


class _Cache:
    """LRU of rendered responses, bounded by entries and by bytes (large full-resolution bodies are not kept)."""

    def __init__(self) -> None:
        self._items: OrderedDict[tuple[object, ...], tuple[bytes, str]] = OrderedDict()
        self._bytes = 0
        self._lock = threading.Lock()

    def get(self, key: tuple[object, ...]) -> tuple[bytes, str] | None:
        with self._lock:
            hit = self._items.get(key)
            if hit is not None:
                self._items.move_to_end(key)
            return hit

    def forget(self, analysis_id: str) -> None:
        """Drop every answer about ``analysis_id`` (deleted: its id must not be served from memory)."""
        with self._lock:
            for key in [k for k in self._items if k[1] == analysis_id]:
                self._bytes -= len(self._items.pop(key)[0])

    def put(self, key: tuple[object, ...], value: tuple[bytes, str], entries: int, max_bytes: int) -> None:
        if len(value[0]) > max_bytes // 8:
            return
        with self._lock:
            old = self._items.pop(key, None)
            self._bytes -= len(old[0]) if old else 0
            self._items[key] = value
            self._bytes += len(value[0])
            while self._items and (len(self._items) > entries or self._bytes > max_bytes):
                _, dropped = self._items.popitem(last=False)
                self._bytes -= len(dropped[0])


_CACHE = _Cache()
ON_DELETE.append(_CACHE.forget)
_SPEED_PATH = re.compile(r"^/analyses/([^/]+)(?:/events/\d+)?/speed$")


def cache_key(scope: Scope) -> tuple[object, ...]:
    """A speed read's cache key: analysis id (second, for :meth:`_Cache.forget`), path, query string and
    whether ``Accept`` asks for CSV -- what decides the answer, read without parsing anything."""
    path = scope["path"]
    m = _SPEED_PATH.match(path)
    accept = next((v for k, v in scope.get("headers", ()) if k == b"accept"), b"")
    return ("speed", m.group(1) if m else "", path, scope.get("query_string", b""), b"text/csv" in accept)


class SeriesCache:
    """Answers a repeated speed read from the response cache before routing (plain ASGI, innermost).

    A cached read's cost was mostly the framework's: matching the route and validating seven query
    parameters took about three quarters of it (cProfile, docs/api.md). Only reads that passed
    validation once are cached (by :func:`get_speed`), and answers of a deleted analysis are
    dropped, so a hit is always the answer the route would give; the request guard and the format
    check have run already (they are outer layers).
    """

    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and scope["method"] == "GET" and scope["path"].endswith("/speed"):
            hit = _CACHE.get(cache_key(scope))
            if hit is not None:
                await Response(hit[0], media_type=hit[1])(scope, receive, send)
                return
        await self.app(scope, receive, send)

INLINE_MAX_POINTS = 5000  # bounded answers from at most INLINE_MAX_ROWS rows are computed on the event loop
INLINE_MAX_ROWS = 1_000_000


def _render(analysis_id: str, event: int | None, t: F64, cols: dict[str, F64], source: int,
            fmt: Literal["json", "csv"]) -> tuple[bytes, str]:
    if fmt == "csv":
        buf = io.StringIO()
        names = list(cols)
        buf.write(",".join(["t_s", *names]) + "\n")
        table = np.column_stack([t, *cols.values()]) if t.size else np.empty((0, 1 + len(names)))
        np.savetxt(buf, table, fmt="%.9g", delimiter=",")
        return buf.getvalue().replace("nan", "").encode(), "text/csv"
    head = json.dumps({"analysis_id": analysis_id, "event": event, "points": int(t.size), "source_points": source,
                       "columns": list(cols)})
    # times to 1 us, values to 0.001 rpm / N m: far below any CAN resolution, and half the bytes of repr()
    parts = [b'"t_s":' + json_numbers(t, 6), *(json.dumps(k).encode() + b":" + json_numbers(v, 3)
                                               for k, v in cols.items())]
    return head[:-1].encode() + b"," + b",".join(parts) + b"}", "application/json"


def _window(t: F64, t0: float | None, t1: float | None) -> slice:
    lo = 0 if t0 is None else int(np.searchsorted(t, t0, side="left"))
    hi = t.size if t1 is None else int(np.searchsorted(t, t1, side="right"))
    if t0 is not None and t1 is not None and t1 < t0:
        raise InputError(f"t1 = {t1} s is before t0 = {t0} s")
    return slice(lo, max(lo, hi))


def _speed(files: ResultFiles, event: int | None) -> tuple[F64, dict[str, F64]]:
    if event is None:
        if not files.has("whole_t"):
            raise NotFoundError("this analysis has no whole-log series (whole_log was off or the simulation failed)")
        return files.array("whole_t"), {c: files.array(f"whole_{c}") for c in SERIES_COLUMNS}
    rows = files.doc["event_rows"].get(str(event))
    if rows is None:
        n = len(files.doc["events"])
        raise NotFoundError(f"event {event} has no aligned series (events 0..{n - 1}; excluded events have none)")
    s = slice(rows[0], rows[1])
    return files.array("ev_t")[s], {c: files.array(f"ev_{c}")[s] for c in SERIES_COLUMNS}


def _wants_csv(request: Request, fmt: str | None) -> Literal["json", "csv"]:
    if fmt is not None:
        return "csv" if fmt == "csv" else "json"
    return "csv" if "text/csv" in request.headers.get("accept", "") else "json"


MaxPoints = Annotated[int, Query(ge=0, le=1_000_000, description="0 = every point")]
MethodQ = Annotated[Literal["minmax", "lttb"], Query(
    description="minmax: each bucket's min and max of every column (no peak lost); "
    "lttb: largest-triangle-three-buckets, one row per bucket")]
Fmt = Annotated[Literal["json", "csv"] | None, Query(alias="format")]
TimeQ = Annotated[float | None, Query(allow_inf_nan=False, description="s from the log start; finite")]


@router.get("/{analysis_id}/speed", responses=SERIES_DOC, response_class=Response,
            summary="Measured vs simulated motor speed (and torque) on a common time base")
async def get_speed(analysis_id: str, request: Request, store: StoreDep, cache: ResultsDep,
                    event: Annotated[int | None, Query(ge=0, description="event index; omit for the whole log")] = None,
                    max_points: MaxPoints = 2000, t0: TimeQ = None, t1: TimeQ = None,
                    fmt: Fmt = None, method: MethodQ = "minmax") -> Response:
    # async on purpose: no thread hop; a miss reads one SQLite row and maps the columns here, and is
    # downsampled here or, when large, in the thread pool (a repeat is answered by SeriesCache)
    out = _wants_csv(request, fmt)
    key = cache_key(request.scope)  # the raw request: SeriesCache answers a repeat before routing

    def columns() -> tuple[F64, dict[str, F64], int]:
        return _speed_columns(store, cache, analysis_id, event, t0, t1, max_points, method)

    return await _answer(request, key, columns, analysis_id, event, max_points, out, method)


async def _answer(request: Request, key: tuple[object, ...], columns: Callable[[], tuple[F64, dict[str, F64], int]],
                  analysis_id: str, event: int | None, max_points: int, out: Literal["json", "csv"],
                  method: Method) -> Response:
    """A series answer from the cache, or computed from ``columns()`` (rows, columns, source rows) and kept."""
    hit = _CACHE.get(key)
    if hit is None:
        t, cols, source = columns()
        args = (analysis_id, event, t, cols, max_points, out, method, source)
        if 0 < max_points <= INLINE_MAX_POINTS and t.size <= INLINE_MAX_ROWS and out == "json" and method == "minmax":
            # A bounded min/max JSON answer from at most a few hundred thousand rows costs about a millisecond
            # (a vectorised pass over memory-mapped columns, compiled number formatting): cheaper on the event
            # loop than a thread hop and the GIL hand-over under concurrency. LTTB (a compiled loop that
            # releases the GIL, several times slower) goes to the thread pool and runs beside the loop.
            hit = _downsampled(*args)
        else:
            hit = await run_in_threadpool(_downsampled, *args)
        cfg = request.app.state.settings
        _CACHE.put(key, hit, cfg.series_cache_entries, int(cfg.series_cache_mb * 2**20))
    return Response(hit[0], media_type=hit[1])


def _speed_columns(store: Store, cache: ResultCache, analysis_id: str, event: int | None, t0: float | None,
                   t1: float | None, max_points: int = 0,
                   method: Method = "minmax") -> tuple[F64, dict[str, F64], int]:
    """The requested rows: views of the memory-mapped result columns, or, for a min/max read of a
    long whole-log window, already the kept rows (from block extremes built once per result)."""
    _, files = finished(store, cache, analysis_id)
    t, cols = _speed(files, event)
    w = _window(t, t0, t1)
    if event is None and method == "minmax" and max_points > 0 and w.stop - w.start > 8 * max_points:
        rows = _extremes(files, cols).rows([np.asarray(v) for v in cols.values()], w.start, w.stop, max_points)
        return np.asarray(t[rows]), {k: np.asarray(v[rows]) for k, v in cols.items()}, w.stop - w.start
    return np.asarray(t[w]), {k: np.asarray(v[w]) for k, v in cols.items()}, w.stop - w.start


def _extremes(files: ResultFiles, cols: dict[str, F64], kind: str = "block_extremes") -> BlockExtremes:
    return files.derived((kind, *cols), lambda: BlockExtremes([np.asarray(v) for v in cols.values()]))


def _signal(files: ResultFiles, name: str) -> tuple[F64, dict[str, F64]]:
    info = files.doc["signals"].get(name)
    if info is None:
        raise NotFoundError(f"no decoded channel {name!r}; have {sorted(files.doc['signals'])}")
    return files.array(f"sig_{info['key']}_t"), {name: files.array(f"sig_{info['key']}_v")}


def _signal_columns(files: ResultFiles, name: str, t0: float | None, t1: float | None, max_points: int,
                    method: Method) -> tuple[F64, dict[str, F64], int]:
    """As :func:`_speed_columns` for one decoded channel: a long min/max window from its block extremes."""
    t, cols = _signal(files, name)
    w = _window(t, t0, t1)
    if method == "minmax" and max_points > 0 and w.stop - w.start > 8 * max_points:
        rows = _extremes(files, cols, "signal_extremes").rows([np.asarray(v) for v in cols.values()],
                                                              w.start, w.stop, max_points)
        return np.asarray(t[rows]), {k: np.asarray(v[rows]) for k, v in cols.items()}, w.stop - w.start
    return np.asarray(t[w]), {k: np.asarray(v[w]) for k, v in cols.items()}, w.stop - w.start


def warm(store: Store, cache: ResultCache, job: JobRecord) -> None:
    """Open a just-finished analysis' results and build its whole-log block extremes (a job-runner hook).

    The first read of a result parses its document and scans the whole-log series and the pedal
    channel once: measured at 200 + 90 + 240 ms on a loaded 2-core machine, on the event loop of the
    first dashboard view after the analysis (``bench/dashboard.py``). Done here, in the runner thread,
    as the job ends; the decoded channels' block extremes also serve every later zoom.
    """
    if job.kind != "analysis":
        return
    _, files = finished(store, cache, job.subject)
    if files.has("whole_t"):
        _extremes(files, _speed(files, None)[1])
    for name in files.doc["signals"]:  # the view reads the pedal channel beside the speed
        _extremes(files, _signal(files, name)[1], "signal_extremes")


def _downsampled(analysis_id: str, event: int | None, t: F64, cols: dict[str, F64], max_points: int,
                 out: Literal["json", "csv"], method: Method, source: int) -> tuple[bytes, str]:
    if max_points:
        t, cols = downsample(t, cols, max_points, method)
    return _render(analysis_id, event, t, cols, source, out)


@router.get("/{analysis_id}/events/{event}/speed", responses=SERIES_DOC, response_class=Response,
            summary="Measured vs simulated speed of one event window")
async def get_event_speed(analysis_id: str, event: int, request: Request, store: StoreDep, cache: ResultsDep,
                          max_points: MaxPoints = 2000, fmt: Fmt = None, method: MethodQ = "minmax") -> Response:
    return await get_speed(analysis_id, request, store, cache, event, max_points, None, None, fmt, method)


@router.get("/{analysis_id}/signals", response_model=SignalsOut, summary="Decoded channels of the analysed log")
async def list_signals(analysis_id: str, store: StoreDep, cache: ResultsDep) -> dict[str, object]:
    # async: one SQLite row and the cached result document, cheaper than a thread hop (first paint reads it)
    _, files = finished(store, cache, analysis_id)
    return {"analysis_id": analysis_id, "signals": files.doc["signals"]}


@router.get("/{analysis_id}/signals/{name}", responses=SERIES_DOC, response_class=Response,
            summary="One decoded channel (its own sample times)")
async def get_signal(analysis_id: str, name: str, request: Request, store: StoreDep, cache: ResultsDep,
                     max_points: MaxPoints = 2000, t0: TimeQ = None, t1: TimeQ = None,
                     fmt: Fmt = None, method: MethodQ = "minmax") -> Response:
    # as the speed: cached by query, bounded min/max answers on the event loop (the whole-log view reads
    # the pedal channel beside the speed rows on its first paint and on every zoom)
    out = _wants_csv(request, fmt)

    def columns() -> tuple[F64, dict[str, F64], int]:
        return _signal_columns(finished(store, cache, analysis_id)[1], name, t0, t1, max_points, method)

    key = ("signal", analysis_id, name, max_points, t0, t1, out, method)
    return await _answer(request, key, columns, analysis_id, None, max_points, out, method)
