"""The request guard: Host allow-list, API keys with scopes, same-origin writes, body cap.

One pure ASGI middleware (no per-request thread hop, streaming responses untouched) decides
before any route runs:

1. **Host.** The ``Host`` header must be a loopback name (``localhost``, ``127.0.0.1``, ``::1``),
   the address the server is bound to, or one of ``LASHSCOPE_ALLOWED_HOSTS`` (``*``: any); otherwise
   400 ``host_not_allowed``. A web page that rebinds its own DNS name to 127.0.0.1 sends its
   own name and is refused (DNS rebinding).
2. **Keys.** When the store holds an active API key, or ever held one (every key revoked: the
   server stays closed; ``--insecure`` opens it), or the server listens on a non-loopback address
   without ``--insecure``, every request but ``/health`` and the API docs needs
   ``Authorization: Bearer <key>``: none 401 ``auth_required``, unknown or revoked 401
   ``invalid_key``, too small a scope 403 ``insufficient_scope``. Reads need ``read``; creating
   things (POST, PUT, PATCH) ``write``; deleting ``admin``. Each key gets
   ``LASHSCOPE_KEY_RATE_PER_S`` requests a second (a token bucket holding ``LASHSCOPE_RATE_BURST_S`` worth);
   past that 429 ``rate_limited`` with ``Retry-After``. A request without a key counts against
   its client address instead (``LASHSCOPE_CLIENT_RATE_PER_S``, the same kind of bucket), so an
   open server cannot be flooded from one address either. (Behind a reverse proxy the address is the
   one it forwards, when it is one of ``LASHSCOPE_TRUSTED_PROXIES``: :mod:`app.api.connections`.)
   A wrong key costs its client address a token of a third bucket
   (``LASHSCOPE_AUTH_FAILURE_RATE_PER_S``); while that is empty the address gets 429 before any key
   it sends is looked at, so keys cannot be guessed at speed. A token longer than
   :data:`~app.storage.keys.MAX_TOKEN_CHARS` is refused unhashed.
3. **Same origin.** Without keys (a workstation on loopback) reads stay open, but a
   state-changing request from a browser must come from the service's own origin or a
   ``--cors-origin``: a foreign ``Origin`` or ``Sec-Fetch-Site: cross-site``/``same-site`` gets 403
   ``cross_origin``, so a web page cannot post to a local server (CSRF). Tools that send no
   ``Origin`` (curl, scripts) are not browsers and pass.
4. **Body cap.** Every body but the streamed uploads (``POST /logs``, ``POST /vehicles``, capped
   by ``LASHSCOPE_MAX_UPLOAD_MB``) is read here up to ``LASHSCOPE_MAX_JSON_KB``: past it 413
   ``body_too_large``; a body that stalls for ``LASHSCOPE_UPLOAD_IDLE_S`` gets 408.

Which keys exist, and what a presented key is, are re-read from the store at most once a second,
so ``lashscope keys create`` or ``revoke`` in another process takes effect on a running server
within a second, and a request costs no database read. Only keys that verified are remembered
(by the SHA-256 of the token, never the token), so wrong keys cost no memory.
"""

from __future__ import annotations

import asyncio
import ipaddress
import json
import time
from collections.abc import Awaitable, Callable, MutableMapping
from typing import Any

from app.settings import Settings
from app.storage.keys import MAX_TOKEN_CHARS, ApiKey, scope_allows, token_digest

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
PUBLIC_PATHS = frozenset({"/", "/health", "/docs", "/docs/oauth2-redirect", "/redoc", "/openapi.json"})
PUBLIC_PREFIXES = ("/static/",)  # the dashboard's own files: the page must load to ask for a key
UPLOAD_ROUTES = frozenset({("POST", "/logs"), ("POST", "/vehicles")})
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
KEYS_RECHECK_S = 1.0
AUTH_BURST_S = 2.0  # failed authentications: two seconds' worth, not a dashboard's burst
MAX_BUCKETS = 4096  # rate buckets kept before idle ones are dropped
MAX_VERIFIED = 1024  # verified keys remembered (one per token in use: only valid ones get in)
CHALLENGE = {"WWW-Authenticate": 'Bearer realm="lashscope"'}


def is_loopback(host: str) -> bool:
    """Whether ``host`` (a name or address, IPv6 possibly in brackets) is this machine only."""
    name = host.strip("[]").lower()
    if name == "localhost":
        return True
    try:
        return ipaddress.ip_address(name).is_loopback
    except ValueError:
        return False


def host_name(header: str) -> str:
    """The name part of a ``Host`` header: ``[::1]:8000`` -> ``::1``, ``example.org:80`` -> ``example.org``."""
    header = header.strip().lower()
    if header.startswith("["):
        return header[1:header.find("]")] if "]" in header else header
    return header.rsplit(":", 1)[0] if header.count(":") == 1 else header


def required_scope(method: str) -> str:
    if method in SAFE_METHODS:
        return "read"
    return "admin" if method == "DELETE" else "write"


class _Deny(Exception):
    def __init__(self, status: int, code: str, detail: str, headers: dict[str, str] | None = None) -> None:
        super().__init__(detail)
        self.status, self.code, self.detail, self.headers = status, code, detail, headers or {}


async def _respond(send: Send, err: _Deny) -> None:
    body = json.dumps({"detail": err.detail, "code": err.code}).encode()
    headers = [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode())]
    headers += [(k.encode(), v.encode()) for k, v in err.headers.items()]
    await send({"type": "http.response.start", "status": err.status, "headers": headers})
    await send({"type": "http.response.body", "body": body})


class RequestGuard:
    def __init__(self, app: ASGIApp, settings: Settings) -> None:
        self.app = app
        self.cfg = settings
        self.any_host = "*" in settings.allowed_hosts
        bound = [] if settings.host in ("0.0.0.0", "::", "") else [settings.host.lower()]
        self.hosts = LOOPBACK_NAMES | {h.lower() for h in settings.allowed_hosts} | set(bound)
        self.open_network = not is_loopback(settings.host) and not settings.insecure
        self._keys_at = -1e9
        self._key_counts = (0, 0)  # (active, issued), re-read once a second
        self._buckets: dict[str, tuple[float, float]] = {}  # key or client -> (tokens, monotonic time)
        self._verified: dict[str, tuple[ApiKey, float]] = {}  # SHA-256 of a valid token -> (key, monotonic time)

    def _keys(self, store: Any) -> tuple[int, int]:
        """``(active, issued)`` keys of the store, re-read at most once a second ((0, 0) before it is open)."""
        now = time.monotonic()
        if store is not None and now - self._keys_at > KEYS_RECHECK_S:
            self._key_counts, self._keys_at = store.key_counts(), now
        return self._key_counts

    def _closed(self, store: Any) -> bool:
        """Whether a request needs a key: keys are active, or were issued and all revoked (unless the
        operator said ``--insecure``), or the server is on the network without ``--insecure``."""
        active, issued = self._keys(store)
        return self.open_network or active > 0 or (issued > 0 and not self.cfg.insecure)

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope.get("headers", [])}
        try:
            self._check(scope, headers)
            has_body = "content-length" in headers or "transfer-encoding" in headers
            if has_body and (scope["method"], scope["path"].rstrip("/")) not in UPLOAD_ROUTES:
                receive = await self._buffered(receive, headers)
        except _Deny as err:
            await _respond(send, err)
            return
        await self.app(scope, receive, send)

    def _check(self, scope: Scope, headers: dict[str, str]) -> None:
        host = host_name(headers.get("host", ""))
        if not self.any_host and host not in self.hosts:
            raise _Deny(400, "host_not_allowed", f"Host {host!r} is not served here; add it to "
                        "LASHSCOPE_ALLOWED_HOSTS (or --allowed-host) to allow it")
        method, path = scope["method"], scope["path"]
        public = path in PUBLIC_PATHS or path.startswith(PUBLIC_PREFIXES)
        if method == "OPTIONS" or (method in SAFE_METHODS and public):
            return
        store = getattr(scope["app"].state, "store", None) if "app" in scope else None
        auth = headers.get("authorization", "")
        need = required_scope(method)
        client = scope.get("client")
        who = f"client {client[0] if client else 'unknown'}"
        if auth or self._closed(store):
            self._authorise(store, auth, need, who)
            return
        self._spend(who, self.cfg.client_rate_per_s, "LASHSCOPE_CLIENT_RATE_PER_S")
        if method not in SAFE_METHODS:
            self._same_origin(scope, headers)

    def _authorise(self, store: Any, auth: str, need: str, who: str) -> None:
        kind, _, token = auth.partition(" ")
        token = token.strip()
        if not auth:
            active, issued = self._keys(store)
            revoked = "every API key of this server has been revoked (the server stays closed; --insecure " \
                "opens it); " if issued and not active else ""
            raise _Deny(401, "auth_required", f"this request needs an API key with scope {need!r}: {revoked}send "
                        "'Authorization: Bearer <key>' (create one with 'lashscope keys create')", CHALLENGE)
        failures = (f"{who} (failed authentications)", self.cfg.auth_failure_rate_per_s,
                    "LASHSCOPE_AUTH_FAILURE_RATE_PER_S")
        self._spend(*failures, take=0, burst_s=AUTH_BURST_S)  # a client guessing keys is turned away unhashed
        bearer = kind.lower() == "bearer" and bool(token)
        key = self._verify(store, token) if bearer else None
        if key is None:
            self._spend(*failures, burst_s=AUTH_BURST_S)
            raise _Deny(401, "invalid_key", "the API key is unknown or revoked" if bearer else
                        "the Authorization header must read 'Bearer <key>'", CHALLENGE)
        if not scope_allows(key.scope, need):
            raise _Deny(403, "insufficient_scope", f"this request needs scope {need!r}; key {key.id} has "
                        f"{key.scope!r}")
        self._spend(f"key {key.id}", self.cfg.key_rate_per_s, "LASHSCOPE_KEY_RATE_PER_S")

    def _verify(self, store: Any, token: str) -> ApiKey | None:
        """``store.verify_key`` of a valid key remembered for a second (a database read per request otherwise).

        Only keys that verified are remembered, by the SHA-256 of the token: wrong keys, however many
        and however long, leave nothing behind. A token over ``MAX_TOKEN_CHARS`` is not even hashed.
        """
        if len(token) > MAX_TOKEN_CHARS or store is None:
            return None
        now = time.monotonic()
        digest = token_digest(token)
        hit = self._verified.get(digest)
        if hit is not None and now - hit[1] <= KEYS_RECHECK_S:
            return hit[0]
        key: ApiKey | None = store.verify_key(token)
        if key is None:
            self._verified.pop(digest, None)
            return None
        if len(self._verified) >= MAX_VERIFIED:
            self._verified = {d: v for d, v in self._verified.items() if now - v[1] <= KEYS_RECHECK_S}
            if len(self._verified) >= MAX_VERIFIED:
                self._verified.clear()
        self._verified[digest] = (key, now)
        return key

    def _spend(self, who: str, rate: float, setting: str, take: float = 1.0, burst_s: float | None = None) -> None:
        """Take ``take`` tokens from ``who``'s bucket (a key or a client address; refilled at ``rate`` a second,
        ``burst_s`` deep, default ``rate_burst_s``); 429 when it holds less than one (``take=0`` only checks that).
        Idle buckets are dropped once there are many (a full bucket holds no state)."""
        if rate <= 0:
            return
        now = time.monotonic()
        if len(self._buckets) >= MAX_BUCKETS:
            self._buckets = {k: v for k, v in self._buckets.items() if now - v[1] < self.cfg.rate_burst_s}
        depth = (self.cfg.rate_burst_s if burst_s is None else burst_s) * rate
        tokens, then = self._buckets.get(who, (depth, now))
        tokens = min(depth, tokens + (now - then) * rate)
        if tokens < 1:
            self._buckets[who] = (tokens, now)
            wait = (1 - tokens) / rate
            raise _Deny(429, "rate_limited", f"{who} is over {rate:g} requests/s ({setting})",
                        {"Retry-After": str(max(1, round(wait + 0.5)))})
        self._buckets[who] = (tokens - take, now)

    def _same_origin(self, scope: Scope, headers: dict[str, str]) -> None:
        site = headers.get("sec-fetch-site")
        if site is not None and site not in ("same-origin", "none"):
            raise _Deny(403, "cross_origin", f"a {site} request may not change anything here (Sec-Fetch-Site); "
                        "send an API key or use the service's own origin")
        origin = headers.get("origin")
        if origin is None:
            return
        own = f"{scope.get('scheme', 'http')}://{headers.get('host', '')}".lower()
        if origin.lower() != own and origin not in self.cfg.cors_origins:
            raise _Deny(403, "cross_origin", f"requests from origin {origin!r} may not change anything here; "
                        "allow it with --cors-origin or send an API key")

    async def _buffered(self, receive: Receive, headers: dict[str, str]) -> Receive:
        """Read the whole (small) body now, capped and timed; hand it to the app from memory."""
        cap = self.cfg.max_json_bytes
        declared = headers.get("content-length", "")
        if declared.isdigit() and int(declared) > cap:
            raise _Deny(413, "body_too_large", f"request body of {int(declared)} bytes is over the "
                        f"{cap} byte cap (LASHSCOPE_MAX_JSON_KB)")
        messages: list[Message] = []
        size = 0
        while True:
            try:
                async with asyncio.timeout(self.cfg.upload_idle_s):  # no task per message, unlike wait_for
                    msg = await receive()
            except TimeoutError:
                raise _Deny(408, "body_timeout", f"no request body data for {self.cfg.upload_idle_s:g} s "
                            "(LASHSCOPE_UPLOAD_IDLE_S)") from None
            messages.append(msg)
            if msg["type"] != "http.request":
                break
            size += len(msg.get("body", b""))
            if size > cap:
                raise _Deny(413, "body_too_large", f"request body is over the {cap} byte cap (LASHSCOPE_MAX_JSON_KB)")
            if not msg.get("more_body", False):
                break

        async def replay() -> Message:
            return messages.pop(0) if messages else await receive()

        return replay
