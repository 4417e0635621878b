"""``Server-Timing: app;dur=<ms>`` on every HTTP response: the time the service spent on it.

The duration runs from the request reaching the outermost layer to the response's status line
being sent (ms), so it holds routing, the request guard, the handler and any compression of the
first body chunk, but not the time a client spends receiving a long body. Browsers show it in
their network panel and expose it to the page (``PerformanceResourceTiming.serverTiming``), which
is how ``bench/dashboard.py`` splits a request's time to first byte into the service's share and
the rest (queueing on a loaded machine, the connection). A plain ASGI layer: streamed responses
(server-sent events) pass through with the header on their first message.
"""

from __future__ import annotations

import time

from starlette.types import ASGIApp, Message, Receive, Scope, Send


class ServerTiming:
    def __init__(self, app: ASGIApp) -> None:
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        start = time.perf_counter()

        async def timed(message: Message) -> None:
            if message["type"] == "http.response.start":
                ms = (time.perf_counter() - start) * 1e3
                message = {**message, "headers": [*message.get("headers", []),
                                                  (b"server-timing", f"app;dur={ms:.2f}".encode())]}
            await send(message)

        await self.app(scope, receive, timed)
