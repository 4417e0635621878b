"""Live sessions: start and stop, status, completed events, and a server-sent-events stream.

``POST /live/sessions`` opens a bus through python-can and starts recording and decoding it;
``GET /live/sessions/{id}`` is its status (frames/s, dropped frames, bus and decode errors,
bus connection state); ``GET /live/sessions/{id}/events`` lists the tip-in/tip-out events
completed so far with their metrics; ``GET /live/sessions/{id}/stream`` is a
``text/event-stream`` of ``samples`` (decoded channels, ~20 updates/s), ``event`` and
``status`` messages for dashboards; ``POST /live/sessions/{id}/stop`` ends the session and
returns the stored log and its analysis.

Interfaces that reach the network (``udp_multicast``, ``socketcand``) are off unless listed in
``LASHSCOPE_LIVE_INTERFACES`` (comma-separated), which replaces the default set. Which bus a client
may open is the operator's choice too: ``LASHSCOPE_LIVE_CHANNELS`` lists ``interface:channel`` pairs
or ``interface:*`` (default ``virtual:*,tcp_loopback:127.0.0.1:29536,socketcan:*``: socketcan channels
are kernel interface names; of the loopback hubs only the one on its default port). Anything else --
e.g. a serial device path for ``slcan``, or another local port -- is 403 ``live_channel_not_allowed``,
and option values that look like file paths are refused the same way.
"""

from __future__ import annotations

import asyncio
import threading
from collections.abc import AsyncIterator
from typing import Annotated, Any

from fastapi import APIRouter, Depends, Request, status
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import StreamingResponse
from pydantic import BaseModel, Field

from app.api.deps import SettingsDep
from app.api.schemas import ERRORS, LiveEventsOut, LiveSessionOut
from app.errors import ForbiddenError, InputError
from app.live.bus import LOOPBACK_INTERFACE, BusConfig
from app.live.decoding import source_for
from app.live.loopback import parse_endpoint, require_loopback
from app.live.manager import LiveManager, StartRequest
from app.live.session import LiveSession
from app.live.stream import sse_format
from app.settings import Settings

router = APIRouter(prefix="/live", tags=["live"], responses=ERRORS)
_lock = threading.Lock()
KEEPALIVE_S = 15.0


class LiveStart(BaseModel):
    interface: str = Field(description="python-can interface, e.g. socketcan, pcan, vector, virtual, tcp_loopback")
    channel: str | None = Field(default=None, description="e.g. vcan0, PCAN_USBBUS1, 127.0.0.1:29536")
    bitrate: int | None = Field(default=None, gt=0)
    options: dict[str, str | int | float | bool] = Field(default_factory=dict,
                                                        description="extra python-can interface arguments")
    vehicle: str | None = Field(default=None, description="registered vehicle: its DBC and signal map decode the bus")
    vehicle_version: int | None = None
    database: str | None = Field(default=None, description="a DBC file name in the service's DBC folder "
                                                           "(instead of a vehicle: decode and stream, no events)")
    analyse: bool = Field(default=True, description="analyse the stored log when the session stops")


class LiveStopped(BaseModel):
    session: dict[str, Any]
    log_id: str | None
    analysis_id: str | None
    note: str | None = None


def _allowed(settings: Settings) -> frozenset[str] | None:
    return frozenset(settings.live_interfaces) or None


def get_manager(request: Request, settings: SettingsDep) -> LiveManager:
    """One manager per app, created on first use (it recovers recordings left by a crash)."""
    with _lock:
        manager: LiveManager | None = getattr(request.app.state, "live", None)
        if manager is None:
            runner = getattr(request.app.state, "runner", None)
            manager = LiveManager(request.app.state.store, settings.data_dir / "live", source_for,
                                  submit=runner.submit if runner is not None else None,
                                  allowed_interfaces=_allowed(settings))
            manager.recover()
            request.app.state.live = manager
    return manager


ManagerDep = Annotated[LiveManager, Depends(get_manager)]


def _database(settings: Settings, name: str) -> Any:
    root = settings.dbc_dir.resolve()
    path = (root / name).resolve()
    if path.parent != root or not path.is_file():
        raise InputError(f"database {name!r} is not a file in the service's DBC folder")
    return path


def _bus_name(interface: str, channel: str | None) -> str:
    """``interface:channel``, a loopback hub's channel as ``address:port`` (``localhost`` -> ``127.0.0.1``,
    no port -> the default), so one hub has one name however it is written."""
    if interface != LOOPBACK_INTERFACE:
        return f"{interface}:{channel or ''}"
    host, port = parse_endpoint(channel)
    return f"{interface}:{require_loopback(host)}:{port}"


def _channel_allowed(settings: Settings, body: LiveStart) -> None:
    """The operator's allow-list decides which bus a client may open, never the client. A loopback hub
    is allowed by its port too (``tcp_loopback:127.0.0.1:29536``): connecting to any local port would
    let a client find out which are open."""
    pair = _bus_name(body.interface, body.channel)
    allowed = {entry if entry.endswith(":*") else _bus_name(*entry.split(":", 1))
               for entry in settings.live_channels if ":" in entry}
    if f"{body.interface}:*" not in allowed and pair not in allowed:
        raise ForbiddenError(f"live bus {pair!r} is not allowed on this server (LASHSCOPE_LIVE_CHANNELS: "
                             f"{', '.join(settings.live_channels) or 'none'})", code="live_channel_not_allowed")
    for key, value in body.options.items():
        if isinstance(value, str) and ("/" in value or "\\" in value):
            raise ForbiddenError(f"live option {key!r}: file or device paths are not accepted from clients",
                                 code="live_channel_not_allowed")


@router.post("/sessions", status_code=status.HTTP_201_CREATED, response_model=LiveSessionOut,
             summary="Start a live session on a CAN bus")
def start_session(body: LiveStart, manager: ManagerDep, settings: SettingsDep) -> dict[str, Any]:
    if body.interface in manager.allowed:  # otherwise the manager names the enabled interfaces
        _channel_allowed(settings, body)
    database = _database(settings, body.database) if body.database else None
    req = StartRequest(BusConfig(body.interface, body.channel, body.bitrate, dict(body.options)),
                       vehicle=body.vehicle, vehicle_version=body.vehicle_version, database=database,
                       analyse=body.analyse)
    return manager.start(req).status()


@router.get("/sessions", response_model=list[LiveSessionOut],
            summary="Live sessions of this server, running and stopped")
def list_sessions(manager: ManagerDep) -> list[dict[str, Any]]:
    return [s.status() for s in manager.sessions()]


@router.get("/sessions/{session_id}", response_model=LiveSessionOut,
            summary="Status: frames/s, dropped frames, bus and decode errors, bus state")
def get_session(session_id: str, manager: ManagerDep) -> dict[str, Any]:
    return manager.get(session_id).status()


@router.get("/sessions/{session_id}/events", response_model=LiveEventsOut,
            summary="Events completed so far, with their ripple metrics")
def get_events(session_id: str, manager: ManagerDep, since: int = 0) -> dict[str, Any]:
    s = manager.get(session_id)
    events = [e for e in list(s.events) if e["index"] >= since]
    return {"session_id": session_id, "count": len(events), "events": events}


@router.post("/sessions/{session_id}/stop", response_model=LiveStopped,
             summary="Stop: the recording becomes a stored log, analysed when a vehicle was given")
async def stop_session(session_id: str, manager: ManagerDep) -> LiveStopped:
    done = await run_in_threadpool(manager.stop, session_id)
    return LiveStopped(session=manager.get(session_id).status(), log_id=done.log_id,
                       analysis_id=done.analysis_id, note=done.note)


async def _events(request: Request, session: LiveSession) -> AsyncIterator[str]:
    sub = session.hub.subscribe()
    if sub is None:
        yield "event: error\ndata: {\"detail\": \"too many stream subscribers\"}\n\n"
        return
    try:
        yield "retry: 2000\n\n"
        idle = 0.0
        while True:
            update, dropped = await run_in_threadpool(sub.get, 0.5)
            if update is None:
                if sub.closed or await request.is_disconnected():
                    return
                idle += 0.5
                if idle >= KEEPALIVE_S:
                    idle = 0.0
                    yield ": keep-alive\n\n"
                continue
            idle = 0.0
            yield sse_format(update, dropped)
            if update.kind == "end":
                return
            await asyncio.sleep(0)
    finally:
        session.hub.unsubscribe(sub)


@router.get("/sessions/{session_id}/stream", summary="Server-sent events: samples, event, status, end",
            response_class=StreamingResponse)
def stream(session_id: str, request: Request, manager: ManagerDep) -> StreamingResponse:
    s = manager.get(session_id)
    return StreamingResponse(_events(request, s), media_type="text/event-stream",
                             headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})
