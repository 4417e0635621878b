"""``lashscope serve``: the REST API on uvicorn (SQLite + files in the data directory)."""

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
    p.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.api.main import create_app
    from app.settings import Settings

    overrides = {k: getattr(args, k) for k in ("host", "port", "data_dir", "max_upload_mb", "analysis_workers",
                                                "cors_origins") if getattr(args, k) is not None}
    settings = Settings(**overrides)
    from app.fleet.hook import enable_for_service

    enable_for_service(settings.data_dir)  # the analyses' events also go to <data dir>/events (Parquet)
    print(f"lashscope: serving on http://{settings.host}:{settings.port} (data in {settings.data_dir.resolve()}; "
          f"API docs at /docs)", flush=True)
    # Without a grace limit uvicorn waits for every open response before the lifespan shutdown, and a
    # server-sent-event stream of a live session stays open until that very shutdown stops the session.
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=args.log_level,
                timeout_graceful_shutdown=settings.shutdown_grace_s)
    return 0
