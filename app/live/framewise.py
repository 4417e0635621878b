"""Per-frame decoding of the mapped signals, for the small batches of a live bus.

The vector decoder (:class:`app.ingest.decode.VectorDecoder`) is built for chunks of
thousands of frames; its cost per call (a few numpy operations per signal) is what a
live session pays for every batch, and at 20 k frames/s a batch is ~20 frames. For batches
that small this module decodes frame by frame with cantools' compiled codec (the reference
the vector decoder is tested against), then applies the same "not available" rule and the
signal map's conversion, so its samples equal the vector path's (a test checks it).

Same semantics as the vector path with the default options: frames match a message by ID
and the extended flag; a frame shorter than the message is left out and counted as
``short_frame``; raw values whose label means "not available" (:func:`is_na_label`) become
NaN; ``value * gain + offset`` as in :func:`app.ingest.pipeline_signals.map_decoded`; rows
from another bus than the map's ``bus`` are left out. Multiplexed messages are not handled
here (the caller uses the vector path for them).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, cast

import numpy as np
from cantools.database.can import Message as CanMessage
from cantools.database.conversion import BaseConversion

from app.ingest.decode import EXTENDED_KEY, is_na_label
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.signalmap import ResolvedChannel


@dataclass(frozen=True)
class _Route:
    channel: str
    signal: str
    conversion: BaseConversion
    na_raw: frozenset[int | float]
    gain: float
    offset: float
    bus: int | None


class FramewiseDecoder:
    """Decode the mapped signals of a few frames with cantools, frame by frame."""

    def __init__(self, resolved: Mapping[str, ResolvedChannel]) -> None:
        self.messages: dict[int, CanMessage] = {}
        self.routes: dict[int, list[_Route]] = {}
        self.supported = True
        for channel, r in resolved.items():
            m = r.message
            if m.is_multiplexed():
                self.supported = False
            key = m.frame_id | (EXTENDED_KEY if m.is_extended_frame else 0)
            self.messages[key] = m
            sig = r.signal
            na = frozenset(k for k, v in (sig.conversion.choices or {}).items() if is_na_label(str(v)))
            self.routes.setdefault(key, []).append(
                _Route(channel, sig.name, sig.conversion, na, r.gain, r.offset, r.spec.bus))

    def decode(self, chunk: FrameChunk) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict[str, int]]:
        """Channel samples ``{channel: (t s, values)}`` and error counts of ``chunk``."""
        t: dict[str, list[float]] = {}
        v: dict[str, list[float]] = {}
        errors: dict[str, int] = {}
        skip = FrameFlag.ERROR | FrameFlag.REMOTE
        for i in range(len(chunk)):
            flags = int(chunk.flags[i])
            if flags & skip:
                continue
            key = int(chunk.arb_id[i]) | (EXTENDED_KEY if flags & FrameFlag.EXTENDED else 0)
            msg = self.messages.get(key)
            if msg is None:
                continue
            n = int(chunk.dlc[i])
            if n < msg.length:
                errors["short_frame"] = errors.get("short_frame", 0) + 1
                continue
            raw = cast(Mapping[str, Any], msg.decode(chunk.data[i, :n].tobytes(), decode_choices=False, scaling=False))
            t_s = int(chunk.t_ns[i]) / 1e9
            bus = int(chunk.channel[i])
            for r in self.routes[key]:
                if r.bus is not None and r.bus != bus:
                    continue
                x = raw[r.signal]
                if x in r.na_raw:
                    value = float("nan")
                else:
                    value = float(cast(float, r.conversion.raw_to_scaled(x, False)))
                    if r.gain != 1.0 or r.offset != 0.0:
                        value = value * r.gain + r.offset
                t.setdefault(r.channel, []).append(t_s)
                v.setdefault(r.channel, []).append(value)
        return {c: (np.asarray(t[c]), np.asarray(v[c], np.float64)) for c in t}, errors
