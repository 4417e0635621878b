"""A live session: receive a bus, record it, decode it, analyse it -- all as frames arrive.

Threads and queues (every queue bounded)::

    bus ──recv──► [receiver] ──► pending frames (≤ max_pending) ──► [worker] ──► BLF recording
                       │ full: frame dropped, counted                  ├──► decode ──► channel buffers
                       ▼                                               │                 ├──► stream hub ──► SSE
                  BusLink: reconnect with backoff                      │                 └──► live analyzer ──► events
                                                                       └──► counters / status

The receiver only stamps the receipt time and queues the message, so it keeps up with
the bus even when the worker is briefly busy. The worker takes everything queued as one
batch (columnar decode amortises per-call cost), writes it to the recording, decodes it
and hands the channel samples to the analyzer and the stream. A frame dropped because the
queue was full is neither recorded nor decoded, so the recording and the analysis always
agree, and the status reports how many were dropped.

Latency (status ``latency_ms``) is measured per frame from its receipt by the receiver
to the moment its decoded samples are in the channel buffers.
"""

from __future__ import annotations

import sys
import threading
import time
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Protocol

import can
import numpy as np

from app.errors import ConflictError
from app.ingest.frames import FrameChunk, FrameFlag
from app.live.bus import BusConfig, BusLink
from app.live.convert import messages_to_chunk
from app.live.counters import Counters, LatencyRing, RateMeter
from app.live.recorder import FlushingBLFWriter
from app.live.stream import StreamHub

F64 = np.ndarray
SWITCH_INTERVAL_S = 0.0005


@dataclass
class Feed:
    """What a channel source made of one batch of frames."""

    channels: dict[str, tuple[np.ndarray, np.ndarray]]  # canonical name -> (t s, values), each (k,)
    unknown_ids: np.ndarray = field(default_factory=lambda: np.empty(0, np.uint32))  # distinct unknown IDs
    unknown_counts: np.ndarray = field(default_factory=lambda: np.empty(0, np.int64))
    decode_errors: dict[str, int] = field(default_factory=dict)


class ChannelSource(Protocol):
    """Turns frames into canonical channel samples (decode + signal map)."""

    def feed(self, chunk: FrameChunk) -> Feed: ...


class EventSink(Protocol):
    """Consumes channel samples and reports completed events (see :mod:`app.live.analyzer`)."""

    def add(self, channels: Mapping[str, tuple[np.ndarray, np.ndarray]]) -> None: ...

    def completed(self, final: bool = False) -> list[dict[str, Any]]: ...


@dataclass
class SessionOptions:
    max_pending: int = 200_000  # frames queued between receiver and worker (~ 10 s at 20 k/s)
    max_batch: int = 8192  # frames per worker batch
    flush_interval_s: float = 0.5  # recording flushed at least this often
    analysis_every_s: float = 0.25  # completed-event check period (wall time)
    status_every_s: float = 1.0  # status updates on the stream
    stream_every_s: float = 0.05  # samples are sent to dashboards in ~20 Hz updates
    stream_max_points: int = 2000  # per channel and update; beyond this, evenly decimated


class LiveSession:
    """Receive, record, decode and analyse one bus until :meth:`stop`.

    Parameters
    ----------
    bus : BusConfig
    source : ChannelSource
        Decoding and channel mapping (e.g. :class:`app.live.decoding.DecodingSource`).
    record_path : Path, optional
        Where the BLF recording goes; None records nothing.
    analyzer : EventSink, optional
        Live event detection; None disables it.
    """

    def __init__(self, bus: BusConfig, source: ChannelSource, *, record_path: Path | None = None,
                 analyzer: EventSink | None = None, options: SessionOptions | None = None,
                 session_id: str | None = None, link: BusLink | None = None) -> None:
        self.id = session_id or uuid.uuid4().hex[:12]
        self.bus = bus
        self.source = source
        self.record_path = record_path
        self.analyzer = analyzer
        self.opt = options or SessionOptions()
        self.link = link or BusLink(bus)
        self.counters = Counters()
        self.latency = LatencyRing()
        self.rate = RateMeter()
        self.hub = StreamHub()
        self.events: list[dict[str, Any]] = []
        self.state = "created"  # created | running | stopping | stopped | failed
        self.error: str | None = None
        self.started_at: datetime | None = None
        self.t0: float = 0.0  # bus time of t = 0 (the recording's start time)
        self._pending: list[tuple[int, can.Message]] = []
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []
        self._writer: FlushingBLFWriter | None = None
        self._stream_buf: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self._last_stream = 0.0
        self.on_event: Callable[[dict[str, Any]], None] | None = None

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> LiveSession:
        if self.state != "created":
            raise ConflictError(f"live session {self.id} is {self.state}; it can be started once")
        self.link.open()  # a wrong interface/channel fails here, at once
        # The receiver holds the GIL while it parses a burst of frames; with the default 5 ms switch
        # interval the worker (and its latency) waits that long. Process-wide, so only ever lowered.
        sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL_S))
        self.t0 = time.time()
        self.started_at = datetime.fromtimestamp(self.t0, UTC)
        if self.record_path is not None:
            self._writer = FlushingBLFWriter(self.record_path, self.t0, flush_interval_s=self.opt.flush_interval_s)
            self.t0 = float(self._writer.start_timestamp or self.t0)  # frame times as the file stores them
        self.state = "running"
        self._threads = [
            threading.Thread(target=self._receive, name=f"live-rx-{self.id}", daemon=True),
            threading.Thread(target=self._work, name=f"live-worker-{self.id}", daemon=True),
        ]
        for th in self._threads:
            th.start()
        return self

    def stop(self, timeout: float = 10.0) -> None:
        """Stop receiving, process what is queued, finish the recording and the analysis."""
        if self.state not in ("running", "failed"):
            return
        self.state = "stopping"
        self._stop.set()
        with self._cond:
            self._cond.notify_all()
        for th in self._threads:
            th.join(timeout)
        self.link.close()
        if self._writer is not None:
            self._writer.stop()
        self.hub.publish("status", self.status())
        self.hub.close()
        self.state = "stopped" if self.error is None else "failed"

    def wait_idle(self, quiet_s: float = 0.3, timeout: float = 30.0) -> bool:
        """Block until no frame has arrived for ``quiet_s`` and the queue is empty (tests, CLI)."""
        deadline = time.monotonic() + timeout
        last = (-1, time.monotonic())
        while time.monotonic() < deadline:
            n = self.counters.frames_received
            if n != last[0]:
                last = (n, time.monotonic())
            elif time.monotonic() - last[1] >= quiet_s and not self._pending and \
                    self.counters.frames_processed + self.counters.frames_dropped >= n:
                return True
            time.sleep(0.02)
        return False

    # -- threads ---------------------------------------------------------------------------
    def _receive(self) -> None:
        c = self.counters
        cap = self.opt.max_pending
        while not self._stop.is_set():
            msg = self.link.recv(0.1)
            if msg is None:
                continue
            now = time.perf_counter_ns()
            c.frames_received += 1
            with self._cond:
                if len(self._pending) >= cap:
                    c.frames_dropped += 1
                    continue
                self._pending.append((now, msg))
                if len(self._pending) == 1:
                    self._cond.notify()

    def _take(self, timeout: float) -> list[tuple[int, can.Message]]:
        with self._cond:
            if not self._pending and not self._stop.is_set():
                self._cond.wait(timeout)
            if len(self._pending) <= self.opt.max_batch:
                batch, self._pending = self._pending, []
            else:
                batch = self._pending[: self.opt.max_batch]
                del self._pending[: self.opt.max_batch]
        return batch

    def _work(self) -> None:
        next_analysis = next_status = time.monotonic()
        try:
            while True:
                batch = self._take(0.05)
                if batch:
                    self._process(batch)
                now = time.monotonic()
                if self._writer is not None:
                    self._writer.tick()
                if now - self._last_stream >= self.opt.stream_every_s:
                    self._flush_stream()
                if self.analyzer is not None and now >= next_analysis:
                    self._emit(self.analyzer.completed())
                    next_analysis = now + self.opt.analysis_every_s
                if now >= next_status:
                    self.rate.update(self.counters.frames_received, now)
                    self.hub.publish("status", self.status())
                    next_status = now + self.opt.status_every_s
                if self._stop.is_set() and not batch and not self._pending:
                    break
            self._flush_stream()
            if self.analyzer is not None:
                self._emit(self.analyzer.completed(final=True))
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.state = "failed"
            self._stop.set()

    # -- per batch -------------------------------------------------------------------------
    def _process(self, batch: list[tuple[int, can.Message]]) -> None:
        c = self.counters
        msgs = [m for _, m in batch]
        writer = self._writer
        for m in msgs:
            if m.is_error_frame:
                c.bus_errors += 1
            elif m.is_remote_frame:
                c.remote_frames += 1
            elif len(m.data) != m.dlc or (len(m.data) > 8 and not m.is_fd):
                c.malformed_frames += 1
            if writer is not None:
                m.channel = None  # one bus per recording: BLF channel 1
                writer.on_message_received(m)
        chunk = messages_to_chunk(msgs, self.t0)
        good = (chunk.flags & (FrameFlag.ERROR | FrameFlag.REMOTE)) == 0
        feed = self.source.feed(chunk if bool(good.all()) else chunk.select(good))
        if self.analyzer is not None:
            self.analyzer.add(feed.channels)
        done = time.perf_counter_ns()
        self.latency.add(done - np.fromiter((r for r, _ in batch), np.int64, len(batch)))
        c.frames_processed += len(batch)
        c.add_unknown(feed.unknown_ids, feed.unknown_counts)
        c.add_decode_errors(feed.decode_errors)
        for name, (t, v) in feed.channels.items():
            if t.size:
                self._stream_buf.setdefault(name, []).append((t, v))

    def _flush_stream(self) -> None:
        self._last_stream = time.monotonic()
        if not self._stream_buf or not self.hub.subscribers:
            self._stream_buf.clear()
            return
        out: dict[str, dict[str, Any]] = {}
        for name, parts in self._stream_buf.items():
            t = np.concatenate([p[0] for p in parts])
            v = np.concatenate([p[1] for p in parts])
            if t.size > self.opt.stream_max_points:
                keep = np.linspace(0, t.size - 1, self.opt.stream_max_points).astype(np.int64)
                t, v = t[keep], v[keep]
            out[name] = {"t": np.round(t, 6).tolist(), "v": v.tolist()}
        self._stream_buf.clear()
        self.hub.publish("samples", {"channels": out})

    def _emit(self, events: list[dict[str, Any]]) -> None:
        for ev in events:
            self.events.append(ev)
            self.hub.publish("event", ev)
            if self.on_event is not None:
                self.on_event(ev)

    # -- status ----------------------------------------------------------------------------
    def status(self) -> dict[str, Any]:
        c = self.counters
        p50, p99 = self.latency.percentiles_ms()
        link = self.link.status
        return {
            "id": self.id,
            "state": self.state,
            "error": self.error,
            "bus": {"interface": self.bus.interface, "channel": self.bus.channel, "state": link.state,
                    "connects": link.connects, "reconnect_attempts": link.reconnect_attempts,
                    "last_error": link.last_error, "retry_in_s": link.retry_in_s},
            "started_at": self.started_at.isoformat() if self.started_at else None,
            "frames_received": c.frames_received,
            "frames_processed": c.frames_processed,
            "frames_dropped": c.frames_dropped,
            "frames_per_s": round(self.rate.rate(), 1),
            "queue_depth": len(self._pending),
            "queue_capacity": self.opt.max_pending,
            "bus_errors": c.bus_errors,
            "remote_frames": c.remote_frames,
            "malformed_frames": c.malformed_frames,
            "decode_errors": sum(c.decode_errors.values()),
            "decode_errors_by_reason": dict(c.decode_errors),
            "unknown_id_frames": c.unknown_id_frames,
            "unknown_ids": {f"0x{k:X}": v for k, v in sorted(c.unknown_ids.items())},
            "latency_ms": {"p50": p50, "p99": p99},
            "events": len(self.events),
            "recording": str(self.record_path) if self.record_path else None,
            "stream_subscribers": self.hub.subscribers,
        }
