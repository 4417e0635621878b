"""python-can :class:`can.Message` objects <-> columnar :class:`FrameChunk` rows.

A live bus delivers one message at a time; the decoder works on columns. The session
collects a batch of messages and turns it into one chunk here. ``t0`` is the bus time
(s, python-can's ``Message.timestamp`` clock) of the measurement start, so chunk times
are integer ns since that start, exactly as a log reader produces them.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import can
import numpy as np

from app.ingest.frames import FrameChunk, FrameFlag


def message_flags(msg: can.Message) -> int:
    flags = 0
    if msg.is_extended_id:
        flags |= FrameFlag.EXTENDED
    if msg.is_fd:
        flags |= FrameFlag.FD
    if msg.is_error_frame:
        flags |= FrameFlag.ERROR
    if msg.is_remote_frame:
        flags |= FrameFlag.REMOTE
    if msg.bitrate_switch:
        flags |= FrameFlag.BRS
    if msg.error_state_indicator:
        flags |= FrameFlag.ESI
    if not msg.is_rx:
        flags |= FrameFlag.TX
    return int(flags)


def messages_to_chunk(msgs: Sequence[can.Message], t0: float, channel: int = 0) -> FrameChunk:
    """Columns for ``msgs``.

    Parameters
    ----------
    msgs : sequence of can.Message, length n
    t0 : float
        Bus time (s) of the measurement start; ``t_ns = int((timestamp - t0) * 1e9)``.
    channel : int
        Channel number recorded for every row (a live session listens on one bus).

    Returns
    -------
    FrameChunk
        ``data`` is (n, 8) unless a frame carries more than 8 bytes, then (n, 64). Bytes
        beyond the received payload are zero; ``dlc`` keeps the length the frame claimed,
        clipped to the row width, so a frame shorter than its DLC decodes as the short
        payload it is.
    """
    n = len(msgs)
    width = 64 if any(len(m.data) > 8 for m in msgs) else 8
    # one pass of attribute reads per column and a single bytes join: per-frame numpy calls would
    # cost more than the decode itself at tens of thousands of frames per second
    t = np.fromiter((m.timestamp for m in msgs), np.float64, n)
    arb = np.fromiter((m.arbitration_id for m in msgs), np.uint32, n)
    flags = np.fromiter((message_flags(m) for m in msgs), np.uint8, n)
    payloads = [bytes(m.data[:width]) if m.data else b"" for m in msgs]
    dlc = np.fromiter((min(m.dlc, width) if m.is_remote_frame else len(p) for m, p in zip(msgs, payloads, strict=True)),
                      np.uint8, n)
    data = np.frombuffer(b"".join(p.ljust(width, b"\0") for p in payloads), np.uint8).reshape(n, width).copy()
    # truncated like python-can's BLFWriter, so live times equal the recording's to the ns
    t_ns = ((t - t0) * 1e9).astype(np.int64)
    return FrameChunk(t_ns, np.full(n, channel, np.int16), arb, flags, dlc, data)


def chunk_to_messages(chunk: FrameChunk, t0: float = 0.0, channel: str | int | None = None) -> Iterator[can.Message]:
    """Messages for the rows of ``chunk`` (timestamps ``t0 + t_ns / 1e9``)."""
    for i in range(len(chunk)):
        f = int(chunk.flags[i])
        n = int(chunk.dlc[i])
        yield can.Message(
            timestamp=t0 + int(chunk.t_ns[i]) / 1e9,
            arbitration_id=int(chunk.arb_id[i]),
            is_extended_id=bool(f & FrameFlag.EXTENDED),
            is_fd=bool(f & FrameFlag.FD),
            is_error_frame=bool(f & FrameFlag.ERROR),
            is_remote_frame=bool(f & FrameFlag.REMOTE),
            bitrate_switch=bool(f & FrameFlag.BRS),
            error_state_indicator=bool(f & FrameFlag.ESI),
            is_rx=not f & FrameFlag.TX,
            dlc=n,
            data=b"" if f & FrameFlag.REMOTE else chunk.data[i, :n].tobytes(),
            channel=channel,
            check=False,
        )
