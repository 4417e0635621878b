"""``format=`` on routes that have one form only: refused with 406, never silently answered as JSON.

Routes that offer CSV declare a ``format`` query parameter (series, signals, events, metrics);
any other API route asked for ``format=csv`` (or anything but ``json``) answers
``406 {"detail": ..., "code": "format_not_available"}``. Which routes declare it is read from
the app's own OpenAPI document (built once), so the rule follows the routes as they are
declared. The check is a plain ASGI layer: streamed responses (live server-sent events)
pass through untouched.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from typing import Any
from urllib.parse import parse_qs

from starlette.types import ASGIApp, Receive, Scope, Send

from app.api.errors import error_response

Matcher = tuple[re.Pattern[str], str, bool]


def format_table(openapi: dict[str, Any]) -> list[Matcher]:
    """(path pattern, method, declares ``format``) for every operation of an OpenAPI document."""
    out: list[Matcher] = []
    for path, ops in openapi.get("paths", {}).items():
        pattern = re.compile("^" + re.sub(r"\{[^}/]+\}", "[^/]+", re.escape(path).replace(r"\{", "{")
                                          .replace(r"\}", "}")) + "$")
        for method, op in ops.items():
            declares = any(p.get("in") == "query" and p.get("name") == "format" for p in op.get("parameters", []))
            out.append((pattern, method.upper(), declares))
    return out


class FormatGuard:
    def __init__(self, app: ASGIApp, openapi: Callable[[], dict[str, Any]]) -> None:
        self.app = app
        self.openapi = openapi
        self._table: list[Matcher] | None = None

    def refuses(self, method: str, path: str) -> bool:
        """True when ``path`` is an API operation and none of its matching operations declares ``format``."""
        if self._table is None:
            self._table = format_table(self.openapi())
        hits = [declares for pattern, m, declares in self._table if m == method and pattern.match(path)]
        return bool(hits) and not any(hits)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] == "http" and b"format=" in scope.get("query_string", b""):
            wanted = parse_qs(scope["query_string"].decode("latin-1")).get("format", [])
            path = scope.get("path", "")
            if wanted and wanted[-1] != "json" and self.refuses(scope.get("method", "GET"), path):
                resp = error_response(406, f"{path} answers JSON only; format={wanted[-1]} is not available here",
                                      "format_not_available")
                await resp(scope, receive, send)
                return
        await self.app(scope, receive, send)
