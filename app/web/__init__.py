"""The dashboard and the offline API docs, served by the API itself.

``install(app)`` mounts the static dashboard (plain ES modules, no build step) at ``/static``,
answers ``/`` with its page, and serves Swagger UI at ``/docs`` from assets shipped in the
package (``static/vendor/``), so the docs work on a machine without internet. ``/redoc`` points
to ``/docs``. Every page talks to the same REST API a script would; it sends the API key a user
entered (kept in the browser's ``localStorage``) as ``Authorization: Bearer``.

Vendored assets (versions and licences in ``static/vendor/*/LICENSE`` and the README):
uPlot 1.6.32 (MIT) and swagger-ui-dist 5.35.0 (Apache-2.0), both from the npm registry.
"""

from __future__ import annotations

from pathlib import Path

from fastapi import FastAPI
from fastapi.openapi.docs import get_swagger_ui_html
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles

STATIC = Path(__file__).parent / "static"
SWAGGER = "/static/vendor/swagger-ui"


def install(app: FastAPI) -> None:
    """Mount the dashboard on ``app``: ``/`` (the page), ``/static/*`` (its files), ``/docs``, ``/redoc``."""
    app.mount("/static", StaticFiles(directory=STATIC), name="static")

    @app.get("/", include_in_schema=False)
    async def dashboard() -> FileResponse:
        return FileResponse(STATIC / "index.html", media_type="text/html", headers={"Cache-Control": "no-cache"})

    @app.get("/docs", include_in_schema=False)
    async def docs() -> HTMLResponse:
        return get_swagger_ui_html(openapi_url=app.openapi_url or "/openapi.json", title=f"{app.title} API",
                                   swagger_js_url=f"{SWAGGER}/swagger-ui-bundle.js",
                                   swagger_css_url=f"{SWAGGER}/swagger-ui.css",
                                   swagger_favicon_url=f"{SWAGGER}/favicon-32x32.png")

    @app.get("/redoc", include_in_schema=False)
    async def redoc() -> RedirectResponse:
        return RedirectResponse("/docs")
