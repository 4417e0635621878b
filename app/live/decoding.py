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

from app.ingest.database import load_database
from app.ingest.decode import EXTENDED_KEY, DecodedMessage, VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.pipeline_signals import map_decoded
from app.ingest.signalmap import load_signal_map
from app.live.session import Feed

Mapper = Callable[[Mapping[str, DecodedMessage]], dict[str, tuple[np.ndarray, np.ndarray]]]


class DecodingSource:
    """Decode batches and map them to canonical channels.

    Parameters
    ----------
    decoder : VectorDecoder
    mapper : callable
        Decoded messages of one batch -> ``{channel: (t s, values)}`` (see :func:`signal_map_mapper`).
    """

    def __init__(self, decoder: VectorDecoder, mapper: Mapper) -> None:
        self.decoder = decoder
        self.mapper = mapper
        keys = [m.frame_id | (EXTENDED_KEY if m.is_extended_frame else 0) for m in decoder.db.messages]
        self._known = np.array(sorted(keys), np.uint64)

    def feed(self, chunk: FrameChunk) -> Feed:
        if not len(chunk):
            return Feed({})
        keys = chunk.arb_id.astype(np.uint64)
        keys |= np.where((chunk.flags & FrameFlag.EXTENDED) != 0, np.uint64(EXTENDED_KEY), np.uint64(0))
        unknown = ~np.isin(keys, self._known)
        ids = counts = np.empty(0, np.int64)
        if unknown.any():
            ids, counts = np.unique(chunk.arb_id[unknown], return_counts=True)
        decoded = self.decoder.decode(chunk)
        errors: dict[str, int] = {}
        for dm in decoded.values():
            for k, v in dm.errors.items():
                errors[k] = errors.get(k, 0) + int(v)
        return Feed(self.mapper(decoded), ids, counts, errors)




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
    decoder = VectorDecoder(db, messages={r.message.name for r in resolved.values()})

    def mapper(decoded: Mapping[str, DecodedMessage]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {c: (t_ns / 1e9, v) for c, (t_ns, v) in map_decoded(decoded, resolved).items()}

    units = {c: (r.unit, r.interp) for c, r in resolved.items()}
    return DecodingSource(decoder, mapper), units
