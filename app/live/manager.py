"""Live sessions of a service: start, look up, stop, and turn each recording into a stored log.

When a session stops, its BLF recording is hashed and added to the store like an upload
(``inspect_log`` counts frames and reports damage), and, when the session named a vehicle,
an analysis of that log is created and handed to the job runner: the stored log and its
analysis are then the same as for an uploaded file.

Recordings live in ``<data_dir>/live/`` (not the store's temp folder, which is emptied at
start-up). A recording left there by a process that died is adopted as a stored log by
:meth:`LiveManager.recover` (the flushing writer kept all but its last second).
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from app.analysis.metrics import MetricParams
from app.errors import ConflictError, InputError, NotFoundError
from app.ingest.inspect import inspect_log
from app.live.analyzer import LiveAnalyzer
from app.live.bus import BusConfig, supported_interfaces
from app.live.session import ChannelSource, LiveSession, SessionOptions
from app.pipeline import free_rotor_inertia
from app.storage.base import Store
from sim import load_vehicle

# Interfaces a REST client may open. udp_multicast sends to the network and socketcand connects
# to any host given, so a server offers them only when its operator lists them explicitly.
NETWORK_INTERFACES = frozenset({"udp_multicast", "socketcand"})

SourceFactory = Callable[[Path, Path | None], tuple[ChannelSource, Mapping[str, Any]]]


@dataclass
class StartRequest:
    bus: BusConfig
    vehicle: str | None = None
    vehicle_version: int | None = None
    database: Path | None = None  # a DBC without a vehicle: decode and stream, no events
    analyse: bool = True  # create an analysis of the stored log when the session stops
    options: SessionOptions = field(default_factory=SessionOptions)


@dataclass
class Finished:
    log_id: str | None
    analysis_id: str | None
    note: str | None = None


def sha256_of(path: Path) -> str:
    h = hashlib.sha256()
    with path.open("rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


class LiveManager:
    """The live sessions of one service process.

    Parameters
    ----------
    store : Store
    live_dir : Path
        Where recordings are written while sessions run.
    make_source : callable
        ``(database, signal_map or None) -> (ChannelSource, channel units)``.
    submit : callable, optional
        Queue an analysis job (the API's job runner); None leaves analyses to the caller.
    allowed_interfaces : set of str, optional
        Interfaces :meth:`start` accepts; default all but :data:`NETWORK_INTERFACES`.
    max_sessions : int
        Sessions running at the same time.
    """

    def __init__(self, store: Store, live_dir: Path, make_source: SourceFactory,
                 submit: Callable[[str], None] | None = None, allowed_interfaces: frozenset[str] | None = None,
                 max_sessions: int = 4) -> None:
        self.store = store
        self.live_dir = live_dir
        self.live_dir.mkdir(parents=True, exist_ok=True)
        self.make_source = make_source
        self.submit = submit
        self.allowed = allowed_interfaces or frozenset(supported_interfaces()) - NETWORK_INTERFACES
        self.max_sessions = max_sessions
        self._sessions: dict[str, LiveSession] = {}
        self._requests: dict[str, StartRequest] = {}
        self._finished: dict[str, Finished] = {}
        self._lock = threading.Lock()

    def start(self, req: StartRequest) -> LiveSession:
        if req.bus.interface not in self.allowed:
            raise InputError(f"interface {req.bus.interface!r} is not enabled for live sessions here; "
                             f"enabled: {', '.join(sorted(self.allowed))}")
        with self._lock:
            running = sum(1 for s in self._sessions.values() if s.state == "running")
            if running >= self.max_sessions:
                raise ConflictError(f"{running} live sessions are running (limit {self.max_sessions}); stop one first")
        source, _units, analyzer = self._decoding(req)
        session = LiveSession(req.bus, source, analyzer=analyzer, options=req.options)
        session.record_path = self.live_dir / f"live-{session.id}.blf"
        session.start()
        with self._lock:
            self._sessions[session.id] = session
            self._requests[session.id] = req
        return session

    def _decoding(self, req: StartRequest) -> tuple[ChannelSource, Mapping[str, Any], LiveAnalyzer | None]:
        if req.vehicle is not None:
            veh = self.store.get_vehicle(req.vehicle, req.vehicle_version)
            source, units = self.make_source(veh.database_path, veh.signal_map_path)
            return source, units, LiveAnalyzer(units, metric_params=_metric_params(veh.driveline_path))
        if req.database is not None:
            source, units = self.make_source(req.database, None)
            return source, units, None
        raise InputError("a live session needs a vehicle (DBC + signal map) or a database to decode the bus")

    def get(self, session_id: str) -> LiveSession:
        with self._lock:
            s = self._sessions.get(session_id)
        if s is None:
            raise NotFoundError(f"no live session {session_id!r}")
        return s

    def sessions(self) -> list[LiveSession]:
        with self._lock:
            return list(self._sessions.values())

    def finished(self, session_id: str) -> Finished | None:
        return self._finished.get(session_id)

    def stop(self, session_id: str) -> Finished:
        """Stop the session and store its recording (and queue its analysis); idempotent."""
        s = self.get(session_id)
        with self._lock:
            done = self._finished.get(session_id)
            if done is not None:
                return done
        s.stop()
        req = self._requests[session_id]
        done = self.adopt(s.record_path, session_id, req.vehicle if req.analyse else None, req.vehicle_version,
                          meta={"live": s.status()})
        with self._lock:
            self._finished[session_id] = done
        return done

    def adopt(self, path: Path | None, session_id: str, vehicle: str | None, version: int | None,
              meta: dict[str, Any] | None = None) -> Finished:
        """Add a recording to the store (and create its analysis)."""
        if path is None or not path.exists():
            return Finished(None, None, "nothing was recorded")
        try:
            info = inspect_log(path)
        except (InputError, ValueError) as exc:  # LogFormatError: no frame was recorded
            path.unlink(missing_ok=True)
            return Finished(None, None, f"recording not stored: {exc}")
        rec, _ = self.store.add_log(
            path, sha256=sha256_of(path), filename=f"live-{session_id}.blf", fmt=info["format"],
            frames=info["frames"], duration_s=info["duration_s"], start_time=info["start_time"],
            issues=info["issues"], meta={"start_clock": info["start_clock"], "channels": info["channels"],
                                         "source": "live", **(meta or {})})
        if vehicle is None:
            return Finished(rec.id, None)
        veh = self.store.get_vehicle(vehicle, version)
        analysis = self.store.create_analysis(rec.id, veh, {})
        if self.submit is not None:
            self.submit(analysis.job.id)
        return Finished(rec.id, analysis.id)

    def recover(self) -> list[Finished]:
        """Store recordings left behind by a process that stopped without finishing them."""
        active = {s.record_path for s in self.sessions()}
        out = []
        for path in sorted(self.live_dir.glob("live-*.blf")):
            if path not in active:
                out.append(self.adopt(path, path.stem.removeprefix("live-"), None, None,
                                      meta={"recovered": True}))
        return out

    def shutdown(self) -> None:
        for s in self.sessions():
            if s.state == "running":
                self.stop(s.id)


def _metric_params(driveline_path: Path) -> MetricParams:
    """The offline analysis' metric thresholds plus the vehicle's free-rotor inertia, so live
    events get the same gap-open estimate as the stored analysis of the recording."""
    return MetricParams(free_rotor_inertia_kgm2=free_rotor_inertia(load_vehicle(driveline_path)))
