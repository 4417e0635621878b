"""Log + database + signal map -> canonical signals and a decode report (what the service pipeline calls).

Frames stream from the reader chunk by chunk through the :class:`~app.ingest.decode.VectorDecoder`
(only the messages the map needs), are converted to canonical channels with the map's units,
signs and bus selection, and are collected; bus statistics (:mod:`app.ingest.stats`) are
gathered on the way. Memory grows with the decoded samples of the mapped channels, not with
the log's other traffic.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import BinaryIO

import numpy as np
import numpy.typing as npt

from app.errors import MissingSignalError
from app.ingest.database import LoadedDatabase
from app.ingest.decode import NA_LABELS, DecodedMessage, VectorDecoder
from app.ingest.frames import FrameChunk
from app.ingest.readers import LogReader, open_log
from app.ingest.signalmap import ResolvedChannel, SignalMap
from app.ingest.stats import DecodeReport, StatsAccumulator
from app.progress import Progress, no_progress
from app.signals.sampling import Spacing, spacing
from app.signals.signal import Interp, Signal, SignalSet

ChannelSamples = tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]


def map_decoded(decoded: Mapping[str, DecodedMessage], resolved: Mapping[str, ResolvedChannel],
                ) -> dict[str, ChannelSamples]:
    """Canonical channel samples ``(t_ns, values)`` from one batch of decoded messages.

    Rows where the signal is absent (other multiplexer branch) or from another bus than the
    map's ``bus`` are left out; values are converted to the canonical unit and sign.
    """
    by_message: dict[tuple[int, bool], DecodedMessage] = {(d.frame_id, d.is_extended): d for d in decoded.values()}
    out: dict[str, ChannelSamples] = {}
    for channel, r in resolved.items():
        dm = by_message.get((r.message.frame_id, bool(r.message.is_extended_frame)))
        if dm is None or r.signal.name not in dm.signals:
            continue
        values, t_ns = dm.signals[r.signal.name], dm.t_ns
        keep = dm.present.get(r.signal.name)  # None: present in every row
        if r.spec.bus is not None:
            on_bus = dm.channel == r.spec.bus
            keep = on_bus if keep is None else keep & on_bus
        if keep is not None:
            values, t_ns = values[keep], t_ns[keep]
        if r.gain != 1.0 or r.offset != 0.0:
            values = values * r.gain + r.offset
        out[channel] = (t_ns, values)
    return out


def _fraction(reader: LogReader) -> float | None:
    """Share of the log read so far, from the reader's public position and size."""
    size, pos = reader.size, reader.position()
    if not size or pos is None:
        return None
    return min(pos / size, 1.0)


def load_signals(
    log: str | os.PathLike[str] | BinaryIO | LogReader,
    db: LoadedDatabase,
    smap: SignalMap,
    *,
    progress: Progress = no_progress,
    require: Sequence[str] = (),
    strict: bool = False,
    na_to_nan: bool = True,
    na_labels: Sequence[str] = NA_LABELS,
    chunk_frames: int = 65536,
) -> tuple[SignalSet, DecodeReport]:
    """Decode a log into canonical :class:`~app.signals.signal.Signal` objects.

    Parameters
    ----------
    log
        Path, binary file object, or an already open reader from :func:`app.ingest.readers.open_log`.
    db
        The loaded database; its repairs are copied into the report.
    smap
        The vehicle's signal map (validated against ``db`` first).
    progress
        :class:`app.progress.Progress`, called as ``progress(fraction, message)`` after each chunk
        (fraction of the file read, 0..1; the message counts the frames read).
    require
        Canonical channels that must come out with samples, e.g. :data:`app.ingest.signalmap.REQUIRED`.
    strict
        Open the log in strict mode (first damage raises) instead of salvaging.

    Returns
    -------
    SignalSet, DecodeReport
        Signals with ``t`` in s since the start of the measurement, canonical units, NaN where
        the bus said "not available"; the report of what was read and found.

    Raises
    ------
    SignalMapError
        The map does not fit the database.
    MissingSignalError
        A channel in ``require`` is not mapped or no frame carried it.
    """
    resolved = smap.resolve(db.db)
    decoder = VectorDecoder(db.db, na_to_nan=na_to_nan, na_labels=na_labels,
                            messages={r.message.name for r in resolved.values()})
    stats = StatsAccumulator(db.db)
    parts: dict[str, list[ChannelSamples]] = {c: [] for c in resolved}
    own = not isinstance(log, LogReader)
    reader = log if isinstance(log, LogReader) else open_log(log, strict=strict, chunk_frames=chunk_frames)
    try:
        chunk: FrameChunk
        for chunk in reader.chunks():
            decoded = stats.add(chunk, decoder)
            for channel, samples in map_decoded(decoded, resolved).items():
                parts[channel].append(samples)
            frac = _fraction(reader)
            progress(frac if frac is not None else 0.0, f"{stats.frames} frames read")
        report = DecodeReport(source=str(getattr(reader, "name", "")), format=reader.meta.format,
                              database=db.name, database_repairs=list(db.repairs),
                              database_notes=list(db.notes))
        stats.fill(report)
        report.reader_issues = list(reader.report.issues)
    finally:
        if own:
            reader.close()
    signals = SignalSet()
    spaced: list[tuple[npt.NDArray[np.float64], Spacing]] = []  # channels of one message share their times
    for channel, r in resolved.items():
        got = parts[channel]
        t_ns = np.concatenate([p[0] for p in got]) if got else np.empty(0, np.int64)
        values = np.concatenate([p[1] for p in got]) if got else np.empty(0)
        labels = {int(k): str(v) for k, v in (r.signal.choices or {}).items()} if r.interp is Interp.PREVIOUS else {}
        signals.add(Signal.from_samples(channel, t_ns / 1e9, values, r.unit, r.interp, labels))
        report.channels[channel] = len(signals[channel])
        t_s = signals[channel].t
        same = next((sp for t_o, sp in spaced if t_o.size == t_s.size and np.array_equal(t_o, t_s)), None)
        if same is None:
            same = spacing(t_s)
            spaced.append((t_s, same))
        report.sampling[channel] = same
    progress(1.0, f"{report.frames_read} frames read, {len(signals)} channels")
    missing = {c: ("not in the signal map" if c not in resolved else
                   f"no frames of {resolved[c].message.name}" + (f" on bus {resolved[c].spec.bus}"
                                                                  if resolved[c].spec.bus is not None else ""))
               for c in require if c not in signals or len(signals[c]) == 0}
    if missing:
        why = "; ".join(f"{c}: {reason}" for c, reason in missing.items())
        raise MissingSignalError(f"required channels missing from {report.source or 'the log'}: {why}")
    return signals, report

