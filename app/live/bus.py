"""Opening python-can buses, and keeping one open when it disappears.

Any interface python-can supports is reachable through :func:`open_bus` (``socketcan``,
``pcan``, ``vector``, ``kvaser``, ``virtual``, ...), plus ``tcp_loopback``
(:mod:`app.live.loopback`), a loopback-only bus shared by processes on machines without
CAN sockets. :class:`BusLink` wraps an open bus for a long-running receiver: when the
bus fails (adapter unplugged, ``ip link set vcan0 down``, hub gone) it closes it and
reopens it with exponential backoff, exposing the state for a status endpoint.
"""

from __future__ import annotations

import contextlib
import os
import socket
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import can

from app.errors import InputError, LiveBusError
from app.live.loopback import LoopbackBus

LOOPBACK_INTERFACE = "tcp_loopback"


def supported_interfaces() -> list[str]:
    """Every interface name :func:`open_bus` accepts."""
    return sorted(set(can.VALID_INTERFACES) | {LOOPBACK_INTERFACE})


@dataclass(frozen=True)
class BusConfig:
    """Which bus to open.

    ``options`` are passed to the python-can interface unchanged (e.g. ``{"fd": True,
    "data_bitrate": 2000000}`` for a CAN FD adapter, ``{"receive_own_messages": True}``).
    """

    interface: str
    channel: str | None = None
    bitrate: int | None = None
    options: Mapping[str, Any] = field(default_factory=dict)

    def describe(self) -> str:
        return f"{self.interface}:{self.channel}" if self.channel else self.interface


def open_bus(cfg: BusConfig) -> can.BusABC:
    """Open the bus ``cfg`` names.

    Raises
    ------
    InputError
        The interface name is not one python-can (or lashscope) provides.
    LiveBusError
        The interface exists but the bus cannot be opened (no driver, no such channel,
        no CAN sockets in this kernel, nothing listening).
    """
    if cfg.interface not in supported_interfaces():
        raise InputError(
            f"CAN interface {cfg.interface!r} is not supported; choose one of: {', '.join(supported_interfaces())}"
        )
    kwargs: dict[str, Any] = dict(cfg.options)
    if cfg.bitrate is not None:
        kwargs["bitrate"] = cfg.bitrate
    try:
        if cfg.interface == LOOPBACK_INTERFACE:
            return LoopbackBus(channel=cfg.channel, **kwargs)
        return can.Bus(interface=cfg.interface, channel=cfg.channel, **kwargs)
    except (can.CanError, OSError, ImportError, ValueError, TypeError, NotImplementedError) as exc:
        hint = ""
        if cfg.interface == "socketcan":
            ok, reason = can_sockets_available(cfg.channel or "vcan0")
            if not ok:
                hint = f" ({reason})"
        raise LiveBusError(f"cannot open CAN bus {cfg.describe()}: {exc}{hint}") from exc


def can_sockets_available(channel: str = "vcan0") -> tuple[bool, str]:
    """Whether this kernel offers SocketCAN and ``channel`` exists; the reason if not."""
    if not hasattr(socket, "AF_CAN"):
        return False, "this Python build has no socket.AF_CAN"
    try:
        s = socket.socket(socket.AF_CAN, socket.SOCK_RAW, socket.CAN_RAW)
    except OSError as exc:
        return False, f"this kernel has no CAN sockets ({exc.strerror or exc}); see scripts/setup-vcan.sh"
    s.close()
    if not os.path.exists(f"/sys/class/net/{channel}"):
        return False, f"no network interface {channel}; run scripts/setup-vcan.sh"
    return True, "ok"


class Backoff:
    """Exponential backoff: ``initial``, ``initial*factor``, ... capped at ``maximum`` seconds."""

    def __init__(self, initial: float = 0.1, factor: float = 2.0, maximum: float = 5.0) -> None:
        if initial <= 0 or factor < 1 or maximum < initial:
            raise InputError(
                f"backoff needs 0 < initial <= maximum and factor >= 1, got {initial}, {factor}, {maximum}")
        self.initial, self.factor, self.maximum = initial, factor, maximum
        self._next = initial

    def next(self) -> float:
        delay = self._next
        self._next = min(self._next * self.factor, self.maximum)
        return delay

    def reset(self) -> None:
        self._next = self.initial


@dataclass
class LinkState:
    """What a status endpoint shows about the bus connection."""

    state: str = "connecting"  # connecting | connected | reconnecting | closed
    connects: int = 0  # successful opens, the first included
    reconnect_attempts: int = 0  # failed opens since the bus last worked, plus earlier ones
    last_error: str | None = None
    retry_in_s: float | None = None  # seconds until the next attempt while reconnecting


class BusLink:
    """A bus that reopens itself with exponential backoff when it fails.

    :meth:`recv` never raises for a bus failure: it returns ``None`` while the bus is
    away and the :attr:`status` says so. Only :meth:`close` ends it.

    Parameters
    ----------
    cfg : BusConfig
    backoff : Backoff, optional
    opener : callable, optional
        How to open the bus (defaults to :func:`open_bus`); a seam for alternative
        transports, not for tests.
    """

    def __init__(self, cfg: BusConfig, backoff: Backoff | None = None,
                 opener: Callable[[BusConfig], can.BusABC] = open_bus) -> None:
        self.cfg = cfg
        self._backoff = backoff or Backoff()
        self._opener = opener
        self._bus: can.BusABC | None = None
        self._retry_at = 0.0
        self._closed = threading.Event()
        self.status = LinkState()

    def open(self, connect_timeout_s: float = 0.0) -> None:
        """Open now, retrying with the link's backoff for up to ``connect_timeout_s`` seconds.

        A bus that is not there yet (adapter being plugged in, hub starting a moment later)
        gets the same exponential backoff as one that disappears later. A configuration the
        interface refuses (:class:`InputError`, e.g. an unknown interface name) fails at once.

        Raises
        ------
        LiveBusError
            The bus could not be opened within ``connect_timeout_s`` (the last attempt's reason,
            with the number of attempts).
        InputError
            ``connect_timeout_s`` is negative or not finite, or the interface name is unknown.
        """
        if not 0.0 <= connect_timeout_s < float("inf"):
            raise InputError(f"connect timeout must be a finite number of seconds >= 0, got {connect_timeout_s}")
        deadline = time.monotonic() + connect_timeout_s
        attempts = 0
        while True:
            attempts += 1
            try:
                self._bus = self._opener(self.cfg)
                break
            except LiveBusError as exc:
                left = deadline - time.monotonic()
                if left <= 0 or self._closed.is_set():
                    if attempts > 1:
                        raise LiveBusError(f"{exc} (gave up after {attempts} attempts in "
                                           f"{connect_timeout_s:g} s)") from exc
                    raise
                delay = min(self._backoff.next(), left)
                st = self.status
                st.state, st.last_error, st.retry_in_s = "connecting", str(exc), delay
                st.reconnect_attempts += 1
                if self._closed.wait(delay):
                    raise
        self._backoff.reset()
        st = self.status
        st.state, st.connects, st.retry_in_s = "connected", st.connects + 1, None

    @property
    def connected(self) -> bool:
        return self._bus is not None

    def _fail(self, exc: BaseException) -> None:
        bus, self._bus = self._bus, None
        if bus is not None:
            with contextlib.suppress(Exception):
                bus.shutdown()
        delay = self._backoff.next()
        self._retry_at = time.monotonic() + delay
        st = self.status
        st.state, st.last_error, st.retry_in_s = "reconnecting", str(exc), delay

    def _try_reopen(self, timeout: float | None) -> bool:
        wait = self._retry_at - time.monotonic()
        if wait > 0:
            self.status.retry_in_s = wait
            self._closed.wait(min(wait, timeout if timeout is not None else wait))
            if time.monotonic() < self._retry_at or self._closed.is_set():
                return False
        self.status.reconnect_attempts += 1
        try:
            self._bus = self._opener(self.cfg)
        except (LiveBusError, InputError) as exc:
            self._fail(exc)
            return False
        self._backoff.reset()
        st = self.status
        st.state, st.connects, st.retry_in_s = "connected", st.connects + 1, None
        return True

    def recv(self, timeout: float | None) -> can.Message | None:
        if self._closed.is_set():
            return None
        if self._bus is None and not self._try_reopen(timeout):
            return None
        assert self._bus is not None
        try:
            return self._bus.recv(timeout)
        except (can.CanError, OSError, ValueError) as exc:
            if self._closed.is_set():
                return None
            self._fail(exc)
            return None

    def send(self, msg: can.Message) -> bool:
        """Send; ``False`` (and a reconnect scheduled) if the bus is away."""
        if self._closed.is_set():
            return False
        if self._bus is None and not self._try_reopen(0.0):
            return False
        assert self._bus is not None
        try:
            self._bus.send(msg)
        except (can.CanError, OSError) as exc:
            self._fail(exc)
            return False
        return True

    def close(self) -> None:
        self._closed.set()
        bus, self._bus = self._bus, None
        if bus is not None:
            bus.shutdown()
        self.status.state, self.status.retry_in_s = "closed", None
