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
from app.live.session import Feed

Mapper = Callable[[Mapping[str, DecodedMessage]], dict[str, tuple[np.ndarray, np.ndarray]]]


class DecodingSource:
    """Decode batches and map them to canonical channels.

    One decode path for every batch size: :class:`~app.ingest.decode.VectorDecoder` plans
    each message once, so a 20-frame live batch costs a few dozen numpy operations and a
    50,000-frame catch-up batch is decoded column-wise at full speed.

    Parameters
    ----------
    decoder : VectorDecoder
    mapper : callable
        Decoded messages of one batch -> ``{channel: (t s, values)}``.
    known : cantools database, optional
        The vehicle's whole database, when ``decoder`` decodes a pruned copy: IDs it defines are
        not counted as unknown.
    """

    SMALL = 256  # batches up to this size look IDs up in a set (cheaper than array calls)

    def __init__(self, decoder: VectorDecoder, mapper: Mapper, known: CanDatabase | None = None) -> None:
        self.decoder = decoder
        self.mapper = mapper
        keys = [m.frame_id | (EXTENDED_KEY if m.is_extended_frame else 0) for m in (known or decoder.db).messages]
        self._known = np.array(sorted(set(keys)), np.uint64)
        self._known_set = frozenset(keys)

    def feed(self, chunk: FrameChunk) -> Feed:
        if not len(chunk):
            return Feed({})
        ids, counts = self._unknown(chunk)
        decoded = self.decoder.decode(chunk)
        errors: dict[str, int] = {}
        for dm in decoded.values():
            for k, v in dm.errors.items():
                errors[k] = errors.get(k, 0) + int(v)
        return Feed(self.mapper(decoded), ids, counts, errors)

    def _unknown(self, chunk: FrameChunk) -> tuple[np.ndarray, np.ndarray]:
        """Distinct IDs the database does not define, and their frame counts."""
        ext = int(FrameFlag.EXTENDED)
        if len(chunk) <= self.SMALL:
            known = self._known_set
            unknown: dict[int, int] = {}
            for arb, flags in zip(chunk.arb_id.tolist(), chunk.flags.tolist(), strict=True):
                if (arb | (EXTENDED_KEY if flags & ext else 0)) not in known:
                    unknown[arb] = unknown.get(arb, 0) + 1
            if not unknown:
                return _NONE, _NONE
            return (np.fromiter(unknown.keys(), np.int64, len(unknown)),
                    np.fromiter(unknown.values(), np.int64, len(unknown)))
        keys = chunk.arb_id.astype(np.uint64)
        keys |= np.where((chunk.flags & ext) != 0, np.uint64(EXTENDED_KEY), np.uint64(0))
        if self._known.size:
            i = np.minimum(np.searchsorted(self._known, keys), self._known.size - 1)
            unknown_rows = self._known[i] != keys
        else:
            unknown_rows = np.ones(keys.size, bool)
        if not unknown_rows.any():
            return _NONE, _NONE
        ids, counts = np.unique(chunk.arb_id[unknown_rows], return_counts=True)
        return ids.astype(np.int64), counts.astype(np.int64)


_NONE = np.empty(0, np.int64)


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
    return DecodingSource(decoder, mapper, known=db), units


def pruned(db: CanDatabase, resolved: Mapping[str, ResolvedChannel]) -> CanDatabase:
    """A copy of ``db`` with only the messages and signals the map reads.

    The vector decoder's cost per call grows with the number of signals, and a live session
    calls it for every small batch (~20 frames per ms at 20 k frames/s), so decoding the CRCs,
    counters and temperatures nobody maps would add to the latency for nothing. Each signal decodes from
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
