"""``HEAD`` on every ``GET`` route: the answer a ``GET`` would get, headers only.

FastAPI registers a ``GET`` route for ``GET`` alone, so ``HEAD`` (what link checkers, proxies and
``curl -I`` send) would be 405. This pure ASGI middleware runs a ``HEAD`` request as a ``GET`` and
passes on the status and headers (``Content-Length`` included) without the body. A streamed answer
(a live session's event stream) is cut after its headers: the route is told that the client has
gone, so it stops instead of producing a body nobody reads. A route without ``GET`` still answers
405.
"""

from __future__ import annotations

from app.api.security import ASGIApp, Message, Receive, Scope, Send


class HeadAsGet:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http" or scope["method"] != "HEAD":
            await self.app(scope, receive, send)
            return
        done = False

        async def headers_only(message: Message) -> None:
            nonlocal done
            if done:
                return
            if message["type"] == "http.response.start":
                await send(message)
                return
            done = True
            await send({"type": "http.response.body", "body": b"", "more_body": False})

        async def gone_once_answered() -> Message:
            return {"type": "http.disconnect"} if done else await receive()

        await self.app({**scope, "method": "GET"}, gone_once_answered, headers_only)
