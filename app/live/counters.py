"""Live session counters: what the status endpoint shows, at constant memory.

Frame rate comes from a short history of (time, count) pairs; latency percentiles from a
ring of the most recent per-frame latencies; unknown IDs are counted per ID up to a cap
(a bus flooded with random IDs must not grow a dict without bound).
"""

from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass, field

import numpy as np

MAX_TRACKED_IDS = 1024
LATENCY_RING = 8192


@dataclass
class RateMeter:
    """Events per second over the last ``window_s`` seconds."""

    window_s: float = 1.0
    _hist: deque[tuple[float, int]] = field(default_factory=deque)

    def update(self, total: int, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        self._hist.append((now, total))
        while len(self._hist) > 2 and now - self._hist[1][0] >= self.window_s:
            self._hist.popleft()

    def rate(self) -> float:
        if len(self._hist) < 2:
            return 0.0
        (t0, c0), (t1, c1) = self._hist[0], self._hist[-1]
        return (c1 - c0) / (t1 - t0) if t1 > t0 else 0.0


class LatencyRing:
    """The most recent per-frame latencies (ns), for p50/p99 in ms."""

    def __init__(self, size: int = LATENCY_RING) -> None:
        self._buf = np.zeros(size, np.int64)
        self._n = 0
        self._lock = threading.Lock()

    def add(self, lat_ns: np.ndarray) -> None:
        with self._lock:
            lat = lat_ns[-self._buf.size:]
            k = lat.size
            start = self._n % self._buf.size
            first = min(k, self._buf.size - start)
            self._buf[start:start + first] = lat[:first]
            self._buf[: k - first] = lat[first:]
            self._n += k

    def percentiles_ms(self, qs: tuple[float, ...] = (50.0, 99.0)) -> list[float | None]:
        with self._lock:
            filled = self._buf[: min(self._n, self._buf.size)]
            if not filled.size:
                return [None for _ in qs]
            return [float(v) / 1e6 for v in np.percentile(filled, qs)]


@dataclass
class Counters:
    """Totals since the session started (written by the session's threads only)."""

    frames_received: int = 0  # taken off the bus (including those later dropped)
    frames_processed: int = 0  # recorded and decoded
    frames_dropped: int = 0  # the bounded queue was full: neither recorded nor decoded
    bus_errors: int = 0  # error frames on the bus
    remote_frames: int = 0
    malformed_frames: int = 0  # payload length disagrees with the DLC, or > 8 bytes without FD
    unknown_id_frames: int = 0  # IDs the database does not define (counted, not errors)
    decode_errors: dict[str, int] = field(default_factory=dict)  # by reason, from the decoder
    unknown_ids: dict[int, int] = field(default_factory=dict)  # first MAX_TRACKED_IDS IDs seen
    unknown_ids_untracked: int = 0

    def add_unknown(self, ids: np.ndarray, counts: np.ndarray) -> None:
        for i, c in zip(ids.tolist(), counts.tolist(), strict=True):
            self.unknown_id_frames += c
            if i in self.unknown_ids:
                self.unknown_ids[i] += c
            elif len(self.unknown_ids) < MAX_TRACKED_IDS:
                self.unknown_ids[i] = c
            else:
                self.unknown_ids_untracked += c

    def add_decode_errors(self, errors: dict[str, int]) -> None:
        for k, v in errors.items():
            if v:
                self.decode_errors[k] = self.decode_errors.get(k, 0) + v
