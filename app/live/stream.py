"""Fan-out of live updates to dashboard subscribers, with bounded memory per subscriber.

The session publishes *updates* (decoded channel samples of one batch, a completed event,
a status snapshot) from its worker thread; each subscriber (one per server-sent-events
connection) reads from its own bounded queue. A slow subscriber never slows the session
or grows memory: when its queue is full its oldest update is discarded and counted, and
the next update it receives says how many it missed.

:func:`sse_format` renders an update as one ``text/event-stream`` message.
"""

from __future__ import annotations

import json
import math
import threading
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass
class Update:
    """One message to subscribers: ``kind`` is ``"samples"``, ``"event"``, ``"status"`` or ``"end"``."""

    kind: str
    data: Mapping[str, Any]
    seq: int = 0


@dataclass
class Subscription:
    """One subscriber's bounded queue."""

    maxlen: int
    _items: deque[Update] = field(default_factory=deque)
    _cond: threading.Condition = field(default_factory=threading.Condition)
    dropped: int = 0
    closed: bool = False

    def put(self, update: Update) -> None:
        with self._cond:
            if len(self._items) >= self.maxlen:
                self._items.popleft()
                self.dropped += 1
            self._items.append(update)
            self._cond.notify()

    def get(self, timeout: float | None = None) -> tuple[Update | None, int]:
        """Next update (None on timeout) and the number dropped since the last call."""
        with self._cond:
            if not self._items and not self.closed:
                self._cond.wait(timeout)
            dropped, self.dropped = self.dropped, 0
            return (self._items.popleft() if self._items else None), dropped

    def close(self) -> None:
        with self._cond:
            self.closed = True
            self._cond.notify_all()


class StreamHub:
    """Publish updates to any number of subscribers (thread-safe)."""

    def __init__(self, queue_len: int = 256, max_subscribers: int = 64) -> None:
        self.queue_len = queue_len
        self.max_subscribers = max_subscribers
        self._subs: list[Subscription] = []
        self._lock = threading.Lock()
        self._seq = 0
        self.closed = False

    @property
    def subscribers(self) -> int:
        return len(self._subs)

    def subscribe(self) -> Subscription | None:
        """A new subscription, or None when ``max_subscribers`` are connected."""
        with self._lock:
            if len(self._subs) >= self.max_subscribers:
                return None
            sub = Subscription(self.queue_len)
            if self.closed:
                sub.close()
            self._subs.append(sub)
            return sub

    def unsubscribe(self, sub: Subscription) -> None:
        with self._lock:
            if sub in self._subs:
                self._subs.remove(sub)
        sub.close()

    def publish(self, kind: str, data: Mapping[str, Any]) -> None:
        with self._lock:
            self._seq += 1
            update = Update(kind, data, self._seq)
            subs = list(self._subs)
        for s in subs:
            s.put(update)

    def close(self) -> None:
        """Send ``end`` and wake every subscriber; later subscribers get closed queues."""
        self.publish("end", {})
        with self._lock:
            self.closed = True
            subs = list(self._subs)
        for s in subs:
            s.close()


def _jsonable(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if hasattr(value, "tolist"):
        return _jsonable(value.tolist())
    return value


def sse_format(update: Update, dropped: int = 0) -> str:
    """One server-sent event: ``id``, ``event`` and a JSON ``data`` line (NaN -> null)."""
    payload = dict(update.data)
    if dropped:
        payload["dropped_updates"] = dropped
    body = json.dumps(_jsonable(payload), separators=(",", ":"), allow_nan=False)
    return f"id: {update.seq}\nevent: {update.kind}\ndata: {body}\n\n"
