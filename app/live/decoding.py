"""Frames -> canonical channels for a live session: the offline decoder and signal map, per batch.

:class:`DecodingSource` runs :class:`app.ingest.decode.VectorDecoder` on each batch the
session hands it, counts frames whose ID the database does not define (counted, not
errors: a real bus carries many messages a vehicle DBC leaves out), adds the decoder's
error counts (short frames, undefined multiplexer values), and maps decoded signals to
canonical channels with the vehicle's signal map through the offline loader's own
:func:`app.ingest.pipeline_signals.map_decoded`, so live samples equal offline ones.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message as CanMessage

from app.ingest.database import load_database
from app.ingest.decode import EXTENDED_KEY, DecodedMessage, VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.pipeline_signals import map_decoded
from app.ingest.signalmap import ResolvedChannel, load_signal_map
from app.live.framewise import FramewiseDecoder
from app.live.session import Feed

Mapper = Callable[[Mapping[str, DecodedMessage]], dict[str, tuple[np.ndarray, np.ndarray]]]


class DecodingSource:
    """Decode batches and map them to canonical channels.

    Parameters
    ----------
    decoder : VectorDecoder
    mapper : callable
        Decoded messages of one batch -> ``{channel: (t s, values)}``.
    known : cantools database, optional
        The vehicle's whole database, when ``decoder`` decodes a pruned copy: IDs it defines are
        not counted as unknown.
    framewise : FramewiseDecoder, optional
        Used instead of the vector decoder for batches of at most ``small_batch`` frames, where
        its per-call overhead would dominate the latency (see :mod:`app.live.framewise`).
    """

    def __init__(self, decoder: VectorDecoder, mapper: Mapper, known: CanDatabase | None = None,
                 framewise: FramewiseDecoder | None = None, small_batch: int = 64) -> None:
        self.decoder = decoder
        self.mapper = mapper
        self.framewise = framewise if framewise is not None and framewise.supported else None
        self.small_batch = small_batch
        keys = [m.frame_id | (EXTENDED_KEY if m.is_extended_frame else 0) for m in (known or decoder.db).messages]
        self._known = np.array(sorted(keys), np.uint64)
        self._known_set = frozenset(keys)

    def feed(self, chunk: FrameChunk) -> Feed:
        if not len(chunk):
            return Feed({})
        if self.framewise is not None and len(chunk) <= self.small_batch:
            return self._feed_small(chunk)
        keys = chunk.arb_id.astype(np.uint64)
        keys |= np.where((chunk.flags & FrameFlag.EXTENDED) != 0, np.uint64(EXTENDED_KEY), np.uint64(0))
        unknown = ~np.isin(keys, self._known)
        ids = counts = np.empty(0, np.int64)
        if unknown.any():
            ids, counts = np.unique(chunk.arb_id[unknown], return_counts=True)
        errors: dict[str, int]
        decoded = self.decoder.decode(chunk)
        errors = {}
        for dm in decoded.values():
            for k, v in dm.errors.items():
                errors[k] = errors.get(k, 0) + int(v)
        return Feed(self.mapper(decoded), ids, counts, errors)

    def _feed_small(self, chunk: FrameChunk) -> Feed:
        assert self.framewise is not None
        unknown: dict[int, int] = {}
        ext = int(FrameFlag.EXTENDED)
        for arb, flags in zip(chunk.arb_id.tolist(), chunk.flags.tolist(), strict=True):
            if (arb | (EXTENDED_KEY if flags & ext else 0)) not in self._known_set:
                unknown[arb] = unknown.get(arb, 0) + 1
        channels, errors = self.framewise.decode(chunk)
        ids = np.fromiter(unknown.keys(), np.int64, len(unknown))
        counts = np.fromiter(unknown.values(), np.int64, len(unknown))
        return Feed(channels, ids, counts, errors)




def all_signals_mapper(decoded: Mapping[str, DecodedMessage]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Every decoded signal as channel ``"Message.Signal"`` (a session without a signal map).

    Rows where a signal is absent (another multiplexer branch) are left out.
    """
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    for name, dm in decoded.items():
        t = dm.t_ns / 1e9
        for sig, values in dm.signals.items():
            present = dm.is_present(sig)
            out[f"{name}.{sig}"] = (t[present], values[present]) if not present.all() else (t, values)
    return out


def source_for(database: Path, signal_map: Path | None) -> tuple[DecodingSource, dict[str, Any]]:
    """A decoding source for a DBC and, optionally, a vehicle signal map.

    Without a map every decoded signal is a channel ``"Message.Signal"`` (streaming only, no
    events). Returns the source and the units/interpolation of each canonical channel.
    """
    db = load_database(database).db
    decoder = VectorDecoder(db)
    if signal_map is None:
        return DecodingSource(decoder, all_signals_mapper), {}
    resolved = load_signal_map(signal_map).resolve(db)
    decoder = VectorDecoder(pruned(db, resolved))

    def mapper(decoded: Mapping[str, DecodedMessage]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {c: (t_ns / 1e9, v) for c, (t_ns, v) in map_decoded(decoded, resolved).items()}

    units = {c: (r.unit, r.interp) for c, r in resolved.items()}
    return DecodingSource(decoder, mapper, known=db, framewise=FramewiseDecoder(resolved)), units


def pruned(db: CanDatabase, resolved: Mapping[str, ResolvedChannel]) -> CanDatabase:
    """A copy of ``db`` with only the messages and signals the map reads.

    The vector decoder's cost per call grows with the number of signals, and a live session
    calls it for every small batch (~20 frames per ms at 20 k frames/s), so decoding the CRCs,
    counters and temperatures nobody maps would dominate the latency. Each signal decodes from
    its own bits, so the kept signals' values are those of the full message; the message length
    is kept, so short frames are refused alike. Multiplexed messages are kept whole.
    """
    keep: dict[str, set[str]] = {}
    for r in resolved.values():
        keep.setdefault(r.message.name, set()).add(r.signal.name)
    messages: list[CanMessage] = []
    for m in db.messages:
        if m.name not in keep:
            continue
        if m.is_multiplexed():
            messages.append(m)
            continue
        messages.append(CanMessage(frame_id=m.frame_id, name=m.name, length=m.length,
                                   signals=[s for s in m.signals if s.name in keep[m.name]],
                                   is_extended_frame=m.is_extended_frame, is_fd=m.is_fd, strict=False))
    return CanDatabase(messages=messages, strict=False)
