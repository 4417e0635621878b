"""``lashscope serve``: the REST API on uvicorn (SQLite + files in the data directory, or ``--store URL``)."""

from __future__ import annotations

import argparse
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "serve", help="run the REST API", description="Run the REST API. Settings also come from LASHSCOPE_* "
        "environment variables (see app/settings.py); options given here win.")
    p.add_argument("--host", default=None, help="interface to bind (default 127.0.0.1; 0.0.0.0 in a container)")
    p.add_argument("--port", type=int, default=None, help="TCP port (default 8000)")
    p.add_argument("--data-dir", default=None, help="SQLite + files live here (default ./lashscope-data)")
    p.add_argument("--max-upload-mb", type=float, default=None, help="upload size cap in MiB (default 1024)")
    p.add_argument("--workers", type=int, default=None, dest="analysis_workers",
                   help="analyses running at the same time (default 1)")
    p.add_argument("--cors-origin", action="append", default=None, dest="cors_origins",
                   help="allow this origin (repeatable)")
    p.add_argument("--store", default=None, dest="store_url",
                   help="the store as a URL: sqlite:////srv/ls/db.sqlite3, or postgresql://user@host:5432/db "
                   "shared by several servers (its files in ?files=DIR or --data-dir; default: the data directory)")
    p.add_argument("--allowed-host", action="append", default=None, dest="allowed_hosts",
                   help="accept this Host header name besides the loopback names (repeatable; '*': any)")
    p.add_argument("--insecure", action="store_true", default=None,
                   help="serve on a non-loopback address without API keys (refused otherwise)")
    p.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    p.set_defaults(func=run)


def refuse_open_network(settings: Any) -> None:
    """A server reachable from other machines needs API keys, unless the operator says ``--insecure``."""
    from app.api.security import is_loopback
    from app.errors import ForbiddenError
    from app.storage.url import open_store

    if is_loopback(settings.host) or settings.insecure:
        return
    store = open_store(settings.store_location, files=settings.data_dir)
    try:
        keys = store.active_keys()
    finally:
        store.close()
    if keys == 0:
        raise ForbiddenError(f"refusing to serve on {settings.host} without API keys: create one with "
                             "'lashscope keys create --scope admin' (same --data-dir), or pass --insecure "
                             "(LASHSCOPE_INSECURE=1) if something in front of this server authenticates",
                             code="keys_required")


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.api.main import create_app
    from app.settings import Settings

    overrides = {k: getattr(args, k) for k in ("host", "port", "data_dir", "max_upload_mb", "analysis_workers",
                                                "cors_origins", "store_url", "allowed_hosts", "insecure")
                 if getattr(args, k) is not None}
    settings = Settings(**overrides)
    refuse_open_network(settings)
    from app.fleet.hook import enable_for_service
    from app.storage.postgres import redact

    enable_for_service(settings.data_dir)  # the analyses' events also go to <data dir>/events (Parquet)
    print(f"lashscope: serving on http://{settings.host}:{settings.port} (store {redact(settings.store_location)}; "
          f"API docs at /docs)", flush=True)
    # Without a grace limit uvicorn waits for every open response before the lifespan shutdown, and a
    # server-sent-event stream of a live session stays open until that very shutdown stops the session.
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=args.log_level,
                timeout_graceful_shutdown=settings.shutdown_grace_s)
    return 0
