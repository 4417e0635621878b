"""One JSON error shape for every failure: ``{"detail": str, "code": str}`` with the right status.

Handlers are looked up by the exception's MRO, so one handler for :class:`AppError` covers
the whole tree; simulator errors map to 422; anything unexpected is logged and becomes a
500 without a traceback in the response. A message is cut to :data:`MAX_DETAIL_CHARS` (an error
that quotes what it was given -- a listing of half a million unknown keys, say -- stays small).
"""

from __future__ import annotations

import errno
import logging

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.errors import AppError
from sim.errors import SimError

log = logging.getLogger("lashscope.api")

FULL_DISK = frozenset({errno.ENOSPC, errno.EDQUOT})
MAX_DETAIL_CHARS = 2000
HTTP_CODES = {400: "bad_request", 404: "not_found", 405: "method_not_allowed", 413: "body_too_large",
              415: "unsupported_media_type", 422: "invalid_input"}


def short_detail(detail: str) -> str:
    """``detail`` cut to ``MAX_DETAIL_CHARS``, saying how much was left out."""
    if len(detail) <= MAX_DETAIL_CHARS:
        return detail
    return f"{detail[:MAX_DETAIL_CHARS]}... ({len(detail) - MAX_DETAIL_CHARS} more characters left out)"


def error_response(status: int, detail: str, code: str) -> JSONResponse:
    return JSONResponse({"detail": short_detail(detail), "code": code}, status_code=status)


async def _app_error(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, AppError)
    if disk_full(exc):
        return error_response(507, "the server's data volume is full; nothing was stored", "storage_full")
    return error_response(exc.status, exc.detail, exc.code)


async def _sim_error(request: Request, exc: Exception) -> JSONResponse:
    return error_response(422, str(exc), getattr(exc, "code", "sim_error"))


async def _validation(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, RequestValidationError)
    parts = []
    for e in exc.errors():
        where = ".".join(str(p) for p in e.get("loc", ()) if p not in ("body", "query", "path"))
        parts.append(f"{where}: {e.get('msg', 'invalid')}" if where else str(e.get("msg", "invalid")))
    return error_response(422, "; ".join(parts) or "invalid request", "validation_error")


async def _http(request: Request, exc: Exception) -> JSONResponse:
    assert isinstance(exc, StarletteHTTPException)
    return error_response(exc.status_code, str(exc.detail), HTTP_CODES.get(exc.status_code, f"http_{exc.status_code}"))


def disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` (or what caused it) is the data volume running out of space or quota."""
    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, OSError) and seen.errno in FULL_DISK:
            return True
        seen = seen.__cause__ or seen.__context__
    return False


async def _unexpected(request: Request, exc: Exception) -> JSONResponse:
    if disk_full(exc):
        log.error("data volume full on %s %s", request.method, request.url.path)
        return error_response(507, "the server's data volume is full; nothing was stored", "storage_full")
    if isinstance(exc, OSError):  # never the path: strerror only
        log.exception("storage error on %s %s", request.method, request.url.path)
        return error_response(500, f"storage error: {exc.strerror or type(exc).__name__}", "storage_error")
    log.exception("unhandled error on %s %s", request.method, request.url.path)
    return error_response(500, f"internal error ({type(exc).__name__}); the server keeps running", "internal_error")


def install(app: FastAPI) -> None:
    app.add_exception_handler(AppError, _app_error)
    app.add_exception_handler(SimError, _sim_error)
    app.add_exception_handler(RequestValidationError, _validation)
    app.add_exception_handler(StarletteHTTPException, _http)
    app.add_exception_handler(Exception, _unexpected)
