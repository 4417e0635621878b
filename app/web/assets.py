"""The dashboard's files served from memory, under a content-hash version, gzip-compressed once.

Why not a plain static mount: on a loaded 2-core machine each file served from disk cost a thread
hop, a ``stat`` and a read, 20-80 ms of service time per file while the page's ten files queued
behind each other (``bench/dashboard.py`` shows the split), and that sat on the first paint. Here
every file under ``static/`` is read once per process into memory, its gzip form made once on the
first request that accepts it (level 9: the cost is paid once, the page's own JS shrinks to about
a third, Swagger UI's 1.7 MB bundle to under 0.5 MB), and answered on the event loop.

Caching: :data:`VERSION` is a hash of every file's path and bytes. The pages refer to
``/static/<VERSION>/...`` (:func:`versioned` rewrites them), and the ES modules' relative imports
stay inside that prefix, so those answers are ``immutable`` for a year: a browser asks again only
after an upgrade changed a file, which changes the prefix. ``/static/<path>`` without the version
(and an old version's prefix, from a page open across an upgrade) is answered with ``no-cache``
and an ``ETag``: revalidated, ``304`` when unchanged.
"""

from __future__ import annotations

import gzip
import hashlib
import mimetypes
import threading
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

from fastapi import Request, Response

from app.errors import NotFoundError

STATIC = Path(__file__).parent / "static"
IMMUTABLE = "public, max-age=31536000, immutable"
REVALIDATE = "no-cache"
COMPRESSIBLE = ("text/", "application/javascript", "application/json", "image/svg+xml")
MIN_GZIP_BYTES = 1024  # below this the header costs about what compression saves


@dataclass
class Asset:
    body: bytes
    media_type: str
    etag: str
    _gz: bytes | None = field(default=None, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    @property
    def compressible(self) -> bool:
        return self.media_type.startswith(COMPRESSIBLE) and len(self.body) >= MIN_GZIP_BYTES

    def gzipped(self) -> bytes:
        """The gzip form, made once (``mtime=0``: the same bytes every time, so one ETag holds)."""
        with self._lock:
            if self._gz is None:
                self._gz = gzip.compress(self.body, compresslevel=9, mtime=0)
            return self._gz


@cache
def _assets() -> dict[str, Asset]:
    out: dict[str, Asset] = {}
    for p in sorted(STATIC.rglob("*")):
        if p.is_file():
            body = p.read_bytes()
            media = mimetypes.guess_type(p.name)[0] or "application/octet-stream"
            if media.startswith("text/") or media == "application/javascript":
                media += "; charset=utf-8"
            out[p.relative_to(STATIC).as_posix()] = Asset(body, media, f'"{hashlib.sha256(body).hexdigest()[:20]}"')
    return out


@cache
def version() -> str:
    """12 hex digits of a hash over every static file's path and content: changes with any file."""
    h = hashlib.sha256()
    for path, a in _assets().items():
        h.update(path.encode() + b"\0" + a.etag.encode())
    return h.hexdigest()[:12]


def versioned(html: str) -> str:
    """``html`` with every ``"/static/`` reference moved under the current version's prefix."""
    return html.replace('"/static/', f'"/static/{version()}/')


INLINED = ("js/early.js",)  # scripts put into the page itself: they must run before any file arrives


@cache
def page() -> str:
    """The dashboard page: :data:`INLINED` scripts in place, every other reference versioned.

    Inlining saves the round trip a blocking ``<script src>`` costs before the page's first reads
    can leave (``early.js``); the tag names the file, so the page also works served as a file.
    """
    html = _assets()["index.html"].body.decode()
    for name in INLINED:
        html = html.replace(f'<script src="/static/{name}"></script>',
                            f"<script>\n{_assets()[name].body.decode()}</script>")
    return versioned(html)


def lookup(path: str) -> tuple[Asset, bool]:
    """The asset at ``path`` (below ``/static/``) and whether it was asked for under the current version."""
    files = _assets()
    if path in files:
        return files[path], False
    head, _, rest = path.partition("/")
    if rest in files:  # under a version prefix: the current one (cache for a year) or an old one (revalidate)
        return files[rest], head == version()
    raise NotFoundError(f"no dashboard file {path!r}")


def respond(request: Request, path: str) -> Response:
    """The asset's answer: ``304`` on a matching ``If-None-Match``, gzip when accepted and worth it."""
    asset, current = lookup(path)
    gz = asset.compressible and "gzip" in request.headers.get("accept-encoding", "")
    etag = asset.etag[:-1] + '-gz"' if gz else asset.etag  # each encoding its own tag (RFC 9110 8.8.3)
    headers = {"Cache-Control": IMMUTABLE if current else REVALIDATE, "ETag": etag}
    if asset.compressible:
        headers["Vary"] = "Accept-Encoding"
    if etag in request.headers.get("if-none-match", ""):
        return Response(status_code=304, headers=headers)
    if gz:
        headers["Content-Encoding"] = "gzip"
    return Response(asset.gzipped() if gz else asset.body, media_type=asset.media_type, headers=headers)
