"""The application factory.

``create_app(settings)`` wires the store (embedded SQLite + files by default, or
``LASHSCOPE_STORE_URL``), the job runner, the request guard (Host allow-list, API keys,
same-origin writes, body cap: :mod:`app.api.security`), CORS and the error handlers, and
includes every router in :data:`ROUTERS` -- append a module's ``router`` there to add a resource.
``format=csv`` on a route without a CSV form is refused with 406 (:mod:`app.api.formats`); the
dashboard and the offline ``/docs`` are mounted last (:mod:`app.web`). Answers of 1 KiB and more
are gzip-compressed for clients that accept it, ``HEAD`` is answered on every ``GET`` route
(:mod:`app.api.head`), and every answer says the service's time on it (``Server-Timing``,
:mod:`app.api.timing`). When an analysis finishes, its results are opened and
their series' block extremes built in the runner thread (:func:`app.api.routes.series.warm`), so the
first dashboard view after it does not pay for them.

On stop (SIGTERM, Ctrl-C) the lifespan closes the job runner to new work (queued jobs stay
queued in SQLite and run after the next start; a running job's worker process is killed, so the
job is cut off and re-run at the next start), stops running live sessions --
each recording becomes a stored log and, when the session named a vehicle, its analysis is
queued -- and closes the store.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

from fastapi import APIRouter, FastAPI
from fastapi.middleware.cors import CORSMiddleware
from fastapi.middleware.gzip import GZipMiddleware

from app import __version__
from app.analysis import downsample
from app.api import errors, numbers, route_errors
from app.api.formats import FormatGuard
from app.api.head import HeadAsGet
from app.api.routes import (
    analyses,
    batches,
    dashboard,
    diagnoses,
    fleet,
    health,
    identifications,
    live,
    logs,
    series,
    vehicles,
)
from app.api.routes.series import SeriesCache
from app.api.security import RequestGuard
from app.api.timing import ServerTiming
from app.jobs import JobRunner
from app.settings import Settings, get_settings
from app.storage.results import ResultCache
from app.storage.url import open_store
from app.tempfiles import temp_dir_of
from app.web import install as install_dashboard

ROUTERS: list[APIRouter] = [health.router, logs.router, vehicles.router, analyses.router, series.router,
                            live.router, diagnoses.router, identifications.router, batches.router, fleet.router,
                            dashboard.router]

log = logging.getLogger("lashscope.api")
GZIP_MIN_BYTES = 1024
GZIP_LEVEL = 1

DESCRIPTION = """EV CAN logs in, driveline shuffle and clunk answers out.

Upload a log, register a vehicle (driveline TOML + DBC + signal map), start an analysis,
then read events, ripple metrics and measured-vs-simulated speed. Every error is JSON
`{"detail": ..., "code": ...}`."""


async def _stop_live_sessions(app: FastAPI) -> None:
    """Stop running live sessions so their recordings become stored logs (and their analyses are queued).

    The manager exists only once the live API has been used (``app.api.routes.live.get_manager``).
    Stopping joins the session threads and hashes the recording, so it runs off the event loop.
    """
    manager = getattr(app.state, "live", None)
    if manager is None:
        return
    try:
        await asyncio.to_thread(manager.shutdown)
    except Exception:  # the store and the job runner must still be closed
        log.exception("stopping live sessions at shutdown failed")
    else:
        log.info("live sessions stopped and their recordings stored")


def _warm_up() -> None:
    """Load the compiled series kernels before the first request (from numba's cache; compiled once)."""
    downsample.warm_up()
    numbers.warm_up()


def create_app(settings: Settings | None = None) -> FastAPI:
    cfg = settings or get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI) -> AsyncIterator[None]:
        store = open_store(cfg.store_location, files=cfg.data_dir)
        store.clean_temp(2 * cfg.upload_idle_s)  # files cut off by a stop (not those another server still receives)
        with temp_dir_of(store.root):  # every temporary file of the server, a library's too, in the data directory
            runner = JobRunner(store, cfg.analysis_workers, cfg.job_max_attempts, cfg.job_timeout_s,
                               lease_s=cfg.job_lease_s, timeouts=cfg.job_timeouts)
            app.state.store, app.state.runner, app.state.settings = store, runner, cfg
            app.state.results = ResultCache()
            runner.on_done.append(lambda job: series.warm(store, app.state.results, job))
            await asyncio.to_thread(_warm_up)
            resumed = runner.start()
            if resumed:
                log.info("resumed %d queued job(s)", len(resumed))
            try:
                yield
            finally:
                # The runner first: analyses queued from here on (those of the live recordings) stay queued in
                # SQLite and run after the next start instead of holding up the exit.
                runner.shutdown(wait=False)
                await _stop_live_sessions(app)
                store.close()

    app = FastAPI(title="lashscope", version=__version__, description=DESCRIPTION, lifespan=lifespan,
                  docs_url=None, redoc_url=None)  # /docs is served from packaged assets (app.web)
    app.state.settings = cfg  # what SettingsDep hands the routes (app.api.deps)
    app.add_middleware(SeriesCache)  # innermost: a repeated speed read is answered before routing
    app.add_middleware(FormatGuard, openapi=app.openapi)  # a 406 passes the guard and CORS
    app.add_middleware(RequestGuard, settings=cfg)  # inside CORS: preflights are answered before it
    if cfg.cors_origins:
        app.add_middleware(CORSMiddleware, allow_origins=cfg.cors_origins, allow_methods=["*"],
                           allow_headers=["*"])
    # gzip for answers of 1 KiB and more when the client accepts it (level 1: most of the size gone for a
    # few ms per MB, bench/dashboard.py prints both); the dashboard's files come compressed already
    app.add_middleware(GZipMiddleware, minimum_size=GZIP_MIN_BYTES, compresslevel=GZIP_LEVEL)
    app.add_middleware(HeadAsGet)  # HEAD runs as GET, answered with the headers only
    app.add_middleware(ServerTiming)  # outermost: the whole of the service's time on a request
    errors.install(app)
    for router in ROUTERS:
        route_errors.apply(router)  # each operation's own error set in the OpenAPI document
        app.include_router(router)
    install_dashboard(app)
    return app
