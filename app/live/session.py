"""A live session: receive a bus, record it, decode it, analyse it -- all as frames arrive.

Threads and queues (every queue bounded)::

    bus ─recv─► [receiver: take what has arrived, decode + map] ─► queue (≤ max_pending frames) ─► [worker]
                     │ queue full: batch dropped before decoding, counted                             │
                     ▼                                                             BLF recording ◄─┤
                BusLink: reconnect with backoff                      live analyzer ─► events  ◄─┤
                                                                     stream hub ─► SSE        ◄─┤
                                                                     counters / status        ◄─┘

The receiver blocks on the bus, so it wakes when a frame arrives; it then takes whatever
else has already arrived (a burst becomes one batch; a backlog becomes a large batch, which
the column-wise decoder handles at a lower cost per frame) and decodes it at once, in the
same thread: no queue hop and no thread switch lie between a frame's receipt and its decoded
samples, so the machine's load cannot add a scheduling delay there. What is not on that
path -- the recording, the event analysis, the dashboard stream -- runs in the worker, which
wakes every ``worker_every_s`` (or when the queue is a quarter full) and takes everything
queued. A batch that does not fit in the queue is dropped before it is decoded, so it is
neither recorded nor analysed: the recording and the analysis always agree, and the status
reports how many frames were dropped.

Latency (status ``latency_ms``) is measured per frame from its receipt (``recv`` returned)
to the moment its decoded, mapped samples exist.
"""

from __future__ import annotations

import sys
import threading
import time
import uuid
from collections import deque
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


@dataclass
class _Batch:
    """Frames the receiver took together, and what the source made of them."""

    msgs: list[can.Message]
    feed: Feed


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
    max_batch: int = 8192  # frames the receiver takes and decodes at once
    max_batch_s: float = 0.0005  # ... and for at most this long after the first one (bounds the latency of a backlog)
    worker_every_s: float = 0.01  # the worker's wake-up period (recording, analysis and stream are not latency-bound)
    flush_interval_s: float = 0.5  # recording flushed at least this often
    analysis_every_s: float = 0.25  # completed-event check period (wall time)
    status_every_s: float = 1.0  # status updates on the stream
    stream_every_s: float = 0.05  # samples are sent to dashboards in ~20 Hz updates
    stream_max_points: int = 2000  # per channel and update; beyond this, evenly decimated
    connect_timeout_s: float = 0.0  # keep retrying (with backoff) a bus that is absent at start this long


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
        self._pending: deque[_Batch] = deque()
        self._queued = 0  # frames in ``_pending``
        self._cond = threading.Condition()
        self._stop = threading.Event()
        self._rx_done = threading.Event()
        self._threads: list[threading.Thread] = []
        self._writer: FlushingBLFWriter | None = None
        self._stream_buf: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
        self._last_stream = 0.0
        self.on_event: Callable[[dict[str, Any]], None] | None = None

    # -- lifecycle -------------------------------------------------------------------------
    def start(self) -> LiveSession:
        if self.state != "created":
            raise ConflictError(f"live session {self.id} is {self.state}; it can be started once")
        self.link.open(self.opt.connect_timeout_s)  # a wrong interface fails here, an absent bus after the timeout
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
        for th in self._threads:  # the receiver first: the worker then drains what it queued
            with self._cond:
                self._cond.notify_all()
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
            elif time.monotonic() - last[1] >= quiet_s and not self._queued and \
                    self.counters.frames_processed + self.counters.frames_dropped >= n:
                return True
            time.sleep(0.02)
        return False

    @property
    def queue_depth(self) -> int:
        """Frames received and decoded, waiting for the worker (recording, analysis)."""
        return self._queued

    # -- threads ---------------------------------------------------------------------------
    def _receive(self) -> None:
        try:
            self._receive_loop()
        except Exception as exc:  # a decoder bug must not pass silently: the session fails visibly
            self.error = f"{type(exc).__name__}: {exc}"
            self.state = "failed"
            self._stop.set()
        finally:
            self._rx_done.set()
            with self._cond:
                self._cond.notify_all()

    def _receive_loop(self) -> None:
        c = self.counters
        link, clock = self.link, time.perf_counter_ns
        cap, max_batch = self.opt.max_pending, self.opt.max_batch
        max_wait = int(self.opt.max_batch_s * 1e9)
        wake_at = max(1, cap // 4)
        while not self._stop.is_set():
            msg = link.recv(0.1)
            if msg is None:
                continue
            first = clock()
            msgs, stamps = [msg], [first]
            while len(msgs) < max_batch:  # whatever else has arrived already: one batch
                more = link.recv(0.0)
                if more is None:
                    break
                msgs.append(more)
                stamps.append(now := clock())
                if now - first > max_wait:
                    break
            n = len(msgs)
            c.frames_received += n
            if self._queued + n > cap:
                c.frames_dropped += n  # before decoding: a machine that cannot keep up does no wasted work
                continue
            chunk = messages_to_chunk(msgs, self.t0)
            good = (chunk.flags & (FrameFlag.ERROR | FrameFlag.REMOTE)) == 0
            feed = self.source.feed(chunk if bool(good.all()) else chunk.select(good))
            done = clock()
            self.latency.add(done - np.array(stamps, np.int64))
            with self._cond:
                self._pending.append(_Batch(msgs, feed))
                self._queued += n
                if self._queued >= wake_at:
                    self._cond.notify()

    def _take(self, timeout: float) -> list[_Batch]:
        with self._cond:
            if self._queued < max(1, self.opt.max_pending // 4) and not self._rx_done.is_set():
                self._cond.wait(timeout)
            batches = list(self._pending)
            self._pending.clear()
        return batches

    def _work(self) -> None:
        next_analysis = next_status = time.monotonic()
        try:
            while True:
                rx_done = self._rx_done.is_set()  # read before taking: nothing is queued after it is set
                batches = self._take(self.opt.worker_every_s)
                for batch in batches:
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
                if rx_done and not self._queued:
                    break
            self._flush_stream()
            if self.analyzer is not None:
                self._emit(self.analyzer.completed(final=True))
        except Exception as exc:
            self.error = f"{type(exc).__name__}: {exc}"
            self.state = "failed"
            self._stop.set()

    # -- per batch -------------------------------------------------------------------------
    def _process(self, batch: _Batch) -> None:
        """Record a decoded batch and hand its samples to the analyzer and the stream (worker thread)."""
        c = self.counters
        writer = self._writer
        for m in batch.msgs:
            if m.is_error_frame:
                c.bus_errors += 1
            elif m.is_remote_frame:
                c.remote_frames += 1
            elif len(m.data) != m.dlc or (len(m.data) > 8 and not m.is_fd):
                c.malformed_frames += 1
            if writer is not None:
                m.channel = None  # one bus per recording: BLF channel 1
                writer.on_message_received(m)
        feed = batch.feed
        if self.analyzer is not None:
            self.analyzer.add(feed.channels)
        c.add_unknown(feed.unknown_ids, feed.unknown_counts)
        c.add_decode_errors(feed.decode_errors)
        for name, (t, v) in feed.channels.items():
            if t.size:
                self._stream_buf.setdefault(name, []).append((t, v))
        with self._cond:
            self._queued -= len(batch.msgs)
        c.frames_processed += len(batch.msgs)

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
            "queue_depth": self._queued,
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
            "recording": self.record_path.name if self.record_path else None,  # a name: where is the server's
            "stream_subscribers": self.hub.subscribers,
        }
