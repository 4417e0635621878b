"""The loopback-only bus shared by processes: content fidelity, loopback enforcement, disappearance."""

from __future__ import annotations

import time

import can
import pytest

from app.errors import InputError
from app.live.bus import Backoff, BusConfig, BusLink, open_bus
from app.live.loopback import LoopbackBus, LoopbackHub, parse_endpoint, require_loopback

FRAMES = [
    can.Message(arbitration_id=0x123, data=bytes(range(8)), is_extended_id=False),
    can.Message(arbitration_id=0x1ABCDEF0, data=b"\x01\x02", is_extended_id=True),
    can.Message(arbitration_id=0x7FF, data=b"", is_extended_id=False),
    can.Message(arbitration_id=0x321, is_remote_frame=True, dlc=4, is_extended_id=False),
    can.Message(arbitration_id=0x18FF00AA, is_fd=True, bitrate_switch=True, error_state_indicator=True,
                data=bytes(range(64)), is_extended_id=True),
    can.Message(arbitration_id=0x20000080, is_error_frame=True, data=bytes(8), is_extended_id=True),
]


def _key(m: can.Message) -> tuple[object, ...]:
    return (m.arbitration_id, m.is_extended_id, m.is_fd, m.is_remote_frame, m.is_error_frame, m.bitrate_switch,
            m.error_state_indicator, m.dlc, bytes(m.data))


def _recv_n(bus: can.BusABC, n: int, timeout: float = 5.0) -> list[can.Message]:
    out: list[can.Message] = []
    deadline = time.monotonic() + timeout
    while len(out) < n and time.monotonic() < deadline:
        m = bus.recv(0.2)
        if m is not None:
            out.append(m)
    return out


def test_hub_forwards_every_frame_kind_to_other_clients_only() -> None:
    with LoopbackHub() as hub:
        a = LoopbackBus(hub.channel)
        b = LoopbackBus(hub.channel)
        c = LoopbackBus(hub.channel)
        try:
            before = time.time()
            for m in FRAMES:
                a.send(m)
            got_b, got_c = _recv_n(b, len(FRAMES)), _recv_n(c, len(FRAMES))
            assert [_key(m) for m in got_b] == [_key(m) for m in FRAMES]
            assert [_key(m) for m in got_c] == [_key(m) for m in FRAMES]
            # the sender does not hear itself (receive_own_messages=False), like a CAN controller
            assert a.recv(0.1) is None
            # timestamps are the hub's receive time: bus time, in python-can's clock
            assert all(before <= m.timestamp <= time.time() for m in got_b)
            assert all(m.is_rx for m in got_b)
        finally:
            for bus in (a, b, c):
                bus.shutdown()


def test_receive_own_messages() -> None:
    with LoopbackHub() as hub:
        a = LoopbackBus(hub.channel, receive_own_messages=True)
        try:
            a.send(FRAMES[0])
            echo = a.recv(1.0)
            assert echo is not None and _key(echo) == _key(FRAMES[0]) and not echo.is_rx
        finally:
            a.shutdown()


@pytest.mark.parametrize("host", ["10.0.0.1", "192.168.1.20", "8.8.8.8"])
def test_non_loopback_hosts_are_refused(host: str) -> None:
    with pytest.raises(InputError, match="not a loopback address"):
        require_loopback(host)
    with pytest.raises(InputError, match="not a loopback address"):
        LoopbackHub(host)
    with pytest.raises(can.CanInitializationError, match="not a loopback address"):
        LoopbackBus(f"{host}:29536")


@pytest.mark.parametrize(("channel", "expected"), [
    ("127.0.0.1:4000", ("127.0.0.1", 4000)), (":4000", ("127.0.0.1", 4000)),
    ("localhost", ("localhost", 29536)), (None, ("127.0.0.1", 29536)),
])
def test_parse_endpoint(channel: str | None, expected: tuple[str, int]) -> None:
    assert parse_endpoint(channel) == expected


def test_no_hub_fails_fast_with_a_typed_error() -> None:
    hub = LoopbackHub().start()
    port = hub.port
    hub.stop()  # nothing listens on this port any more
    t = time.monotonic()
    with pytest.raises(Exception, match="cannot open CAN bus tcp_loopback") as err:
        open_bus(BusConfig("tcp_loopback", f"127.0.0.1:{port}"))
    assert err.type.__name__ == "LiveBusError"
    assert time.monotonic() - t < 2.0


def test_unknown_interface_lists_the_supported_ones() -> None:
    with pytest.raises(InputError, match="virtual"):
        open_bus(BusConfig("no_such_interface", "x"))


def test_vanishing_hub_is_reported_and_link_reconnects_with_backoff() -> None:
    hub = LoopbackHub().start()
    port = hub.port
    link = BusLink(BusConfig("tcp_loopback", hub.channel), backoff=Backoff(0.05, 2.0, 0.4))
    link.open()
    sender = LoopbackBus(hub.channel)
    try:
        sender.send(FRAMES[0])
        assert link.recv(2.0) is not None
        hub.stop()  # the bus disappears
        assert link.recv(1.0) is None
        assert link.status.state == "reconnecting"
        assert "closed the connection" in (link.status.last_error or "")
        # while the hub is away each attempt fails and the delay grows (0.05, 0.1, 0.2, 0.4, 0.4 ...)
        t_end = time.monotonic() + 1.0
        while time.monotonic() < t_end:
            link.recv(0.1)
        attempts = link.status.reconnect_attempts
        assert 2 <= attempts <= 6, attempts
        hub = LoopbackHub(port=port).start()  # it comes back on the same port
        sender.shutdown()
        sender = LoopbackBus(hub.channel)
        deadline = time.monotonic() + 3.0
        while link.status.state != "connected" and time.monotonic() < deadline:
            link.recv(0.1)
        assert link.status.state == "connected" and link.status.connects == 2
        time.sleep(0.05)
        sender.send(FRAMES[1])
        got = None
        deadline = time.monotonic() + 2.0
        while got is None and time.monotonic() < deadline:
            got = link.recv(0.2)
        assert got is not None and _key(got) == _key(FRAMES[1])
    finally:
        sender.shutdown()
        link.close()
        hub.stop()
