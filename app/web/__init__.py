"""The dashboard and the offline API docs, served by the API itself.

``install(app)`` serves the static dashboard (plain ES modules, no build step) at ``/static``
from memory, under a content-hash version with long cache headers and gzip (:mod:`app.web.assets`),
answers ``/`` with its page, and serves Swagger UI at ``/docs`` from assets shipped in the
package (``static/vendor/``), so the docs work on a machine without internet. ``/redoc`` points
to ``/docs``. Every page talks to the same REST API a script would; it sends the API key a user
entered (kept in the browser's ``localStorage``) as ``Authorization: Bearer``.

Vendored assets (versions and licences in ``static/vendor/*/LICENSE`` and the README):
uPlot 1.6.32 (MIT) and swagger-ui-dist 5.35.0 (Apache-2.0), both from the npm registry.
"""

from __future__ import annotations

from fastapi import FastAPI, Request, Response
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import HTMLResponse, RedirectResponse

from app.web import assets
from app.web.assets import STATIC

__all__ = ["STATIC", "install"]


def install(app: FastAPI) -> None:
    """Add the dashboard to ``app``: ``/`` (the page), ``/static/*`` (its files), ``/docs``, ``/redoc``."""

    @app.api_route("/static/{path:path}", methods=["GET", "HEAD"], include_in_schema=False)
    async def static(path: str, request: Request) -> Response:
        return assets.respond(request, path)

    @app.get("/", include_in_schema=False)
    async def dashboard() -> HTMLResponse:
        # no-cache: the page names the current asset version, so it is revalidated on every visit
        return HTMLResponse(assets.page(), headers={"Cache-Control": "no-cache"})

    @app.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        swagger = f"/static/{assets.version()}/vendor/swagger-ui"
        return get_swagger_ui_html(openapi_url=app.openapi_url or "/openapi.json", title=f"{app.title} API",
                                   swagger_js_url=f"{swagger}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{swagger}/swagger-ui.css",
                                   swagger_favicon_url=f"{swagger}/favicon-32x32.png")

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> RedirectResponse:
        return RedirectResponse("/docs")
