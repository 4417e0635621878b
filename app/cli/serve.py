"""``lashscope serve``: the REST API on uvicorn (SQLite + files in the data directory, or ``--store URL``).

uvicorn runs with the connection-level limits of :mod:`app.api.connections` (its own protocol class on
the same httptools parser), and believes forwarded client addresses only from ``--trusted-proxy``."""

from __future__ import annotations

import argparse
from typing import Any

# connection-level limits (app/api/connections.py): option, setting, type, help
LIMIT_FLAGS: tuple[tuple[str, str, type, str], ...] = (
    ("--max-connections", "max_connections", int, "connections open at once (default 1000)"),
    ("--max-client-connections", "max_client_connections", int, "connections per client address (default 64)"),
    ("--header-timeout", "header_timeout_s", float, "seconds a request's head may take to arrive (default 10)"),
    ("--body-timeout", "body_timeout_s", float, "seconds a request's body may take to arrive (default 900)"),
    ("--keep-alive", "keep_alive_s", int, "seconds an idle kept-alive connection stays open (default 5)"),
    ("--max-header-kb", "max_header_kb", float, "cap of a request's line and headers in KiB (default 64)"),
    ("--max-headers", "max_headers", int, "header lines a request may have (default 100)"),
    ("--max-url-kb", "max_url_kb", float, "request URL cap in KiB (default 8)"),
)
SETTING_ARGS = ("host", "port", "data_dir", "max_upload_mb", "analysis_workers", "cors_origins", "store_url",
                "allowed_hosts", "insecure", "trusted_proxies", *(dest for _, dest, _, _ in LIMIT_FLAGS))


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
    p.add_argument("--trusted-proxy", action="append", default=None, dest="trusted_proxies",
                   help="believe X-Forwarded-For/-Proto from this reverse proxy (address or network; repeatable); "
                   "ignored from anyone else")
    for flag, dest, kind, what in LIMIT_FLAGS:
        p.add_argument(flag, type=kind, default=None, dest=dest, help=what)
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


def settings_from(args: argparse.Namespace) -> Any:
    """The environment's settings with the options given on the command line; a bad value is an InputError
    naming the setting, not a traceback."""
    from pydantic import ValidationError

    from app.errors import InputError
    from app.settings import Settings

    try:
        return Settings(**{k: getattr(args, k) for k in SETTING_ARGS if getattr(args, k) is not None})
    except ValidationError as exc:
        problems = "; ".join(f"{'.'.join(map(str, e['loc']))}: {e['msg']}" for e in exc.errors())
        raise InputError(f"invalid setting: {problems}", code="invalid_setting") from None


def uvicorn_options(settings: Any) -> dict[str, Any]:
    """uvicorn's options for ``settings``: the limited protocol, keep-alive, forwarded headers, shutdown grace."""
    from app.api.connections import protocol_class
    from app.settings import parse_networks

    # Without a grace limit uvicorn waits for every open response before the lifespan shutdown, and a
    # server-sent-event stream of a live session stays open until that very shutdown stops the session.
    # Forwarded addresses are believed only from the trusted proxies (uvicorn's default trusts 127.0.0.1, so
    # any local process, or a proxy passing the header through, could pose as any client). They go to uvicorn
    # normalised (10.0.0.1/8 -> 10.0.0.0/8), which it would otherwise take for a name that never matches.
    proxies = [str(net) for net in parse_networks(settings.trusted_proxies)]
    return {"http": protocol_class(settings), "timeout_keep_alive": settings.keep_alive_s,
            "timeout_graceful_shutdown": settings.shutdown_grace_s, "proxy_headers": bool(proxies),
            "forwarded_allow_ips": proxies or None}


def run(args: argparse.Namespace) -> int:
    import uvicorn

    from app.api.connections import fit_to_file_limit
    from app.api.main import create_app

    settings = settings_from(args)
    refuse_open_network(settings)
    allowed = fit_to_file_limit(settings.max_connections)
    if allowed < settings.max_connections:
        print(f"lashscope: the process may open few file handles: serving at most {allowed} connections "
              f"(LASHSCOPE_MAX_CONNECTIONS {settings.max_connections})", flush=True)
        settings = settings.model_copy(update={"max_connections": allowed})
    from app.fleet.hook import enable_for_service
    from app.storage.postgres import redact

    enable_for_service(settings.data_dir)  # the analyses' events also go to <data dir>/events (Parquet)
    print(f"lashscope: serving on http://{settings.host}:{settings.port} (store {redact(settings.store_location)}; "
          f"API docs at /docs)", flush=True)
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=args.log_level,
                **uvicorn_options(settings))
    return 0
