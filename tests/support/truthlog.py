"""Truth drives as real CAN logs: encoded through a DBC into a BLF file, read back through the product's ingest.

The diagnosis is validated on what a user would hand it: a BLF log of a vehicle's bus, decoded
with the vehicle's DBC and signal map. :func:`write_blf` packs the frames of
:func:`.synthetic.measure_frames` into the messages the signal map names for ``motor_torque_nm``
and ``motor_speed_rpm`` (e.g. ``MCU_Torque`` / ``MCU_Speed`` of ``dbc/lashscope_ev.dbc`` at 10 ms,
or both in ``MCU_Fast`` at 1 ms), encoding each frame with the DBC -- so values carry its
quantisation and range -- and writes them in time order with python-can's ``BLFWriter``. The other
signals of those messages get plausible contents: alive counters count through the DBC's range
*in the sender's sequence* (a dropped frame leaves a gap, as on a real bus), a torque request
equal to the actual torque, a "Torque" state, temperatures at 40 degC.

:func:`read_log` is the ingest path of the service: ``open_log`` (format by content) and
``load_signals`` with the database and signal map.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import numpy as np

from app.errors import InputError
from app.ingest.database import LoadedDatabase, load_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.readers import open_log
from app.ingest.signalmap import SignalMap, load_signal_map
from app.ingest.stats import counter_modulus
from app.signals import SignalSet
from tests.support.synthetic import Frames

CHANNELS = ("motor_torque_nm", "motor_speed_rpm")


def _filler(sig: object, value_of: Mapping[str, np.ndarray], seq: np.ndarray) -> np.ndarray:
    """Contents of a signal no channel feeds: counter, request = actual, state, temperature, else 0."""
    name = str(getattr(sig, "name", ""))
    mod = counter_modulus(sig)  # type: ignore[arg-type]
    if mod is not None:
        return np.asarray(seq % mod, dtype=np.float64)
    low = name.lower()
    if "request" in low and "torque" in low and "motor_torque_nm" in value_of:
        return value_of["motor_torque_nm"]
    choices = getattr(sig, "choices", None) or {}
    for raw, label in choices.items():
        if str(label).lower() == "torque":
            return np.full(seq.size, float(raw))
    if "temp" in low:
        return np.full(seq.size, 40.0)
    return np.zeros(seq.size)


def write_blf(path: Path, frames: Mapping[str, Frames], db: LoadedDatabase, smap: SignalMap,
              start_epoch_s: float = 1.7e9) -> int:
    """Encode ``frames`` (by canonical channel) into the map's messages and write a BLF log; returns the frame count.

    Channels that share a message must share timestamps (one frame carries both).

    Raises
    ------
    InputError
        A channel is not in the map, or two channels of one message disagree on their frame times.
    """
    import can  # the writer side of the benchmark and tests; the service itself never writes BLF

    resolved = smap.resolve(db.db)
    by_message: dict[str, list[str]] = {}
    for ch in frames:
        if ch not in resolved:
            raise InputError(f"channel {ch} is not in the signal map {smap.where()}")
        by_message.setdefault(resolved[ch].message.name, []).append(ch)
    rows: list[tuple[float, int, bool, bytes]] = []
    for msg_name, chans in by_message.items():
        first = frames[chans[0]]
        for ch in chans[1:]:
            if not np.array_equal(frames[ch].t, first.t):
                raise InputError(f"{chans[0]} and {ch} share message {msg_name} but not their frame times")
        msg = resolved[chans[0]].message
        values = {ch: (frames[ch].values - resolved[ch].offset) / resolved[ch].gain for ch in chans}
        cols: dict[str, np.ndarray] = {resolved[ch].signal.name: values[ch] for ch in chans}
        for sig in msg.signals:
            if sig.name not in cols:
                cols[sig.name] = _filler(sig, values, first.seq)
        names = list(cols)
        table = np.column_stack([cols[n] for n in names])
        for k in range(first.t.size):
            data = msg.encode(dict(zip(names, table[k].tolist(), strict=True)), scaling=True, strict=True)
            rows.append((float(first.t[k]), int(msg.frame_id), bool(msg.is_extended_frame), bytes(data)))
    rows.sort(key=lambda r: (r[0], r[1]))
    path.parent.mkdir(parents=True, exist_ok=True)
    with can.BLFWriter(str(path)) as writer:
        for ts, arb, ext, data in rows:
            writer.on_message_received(can.Message(timestamp=start_epoch_s + ts, arbitration_id=arb,
                                                   is_extended_id=ext, data=data, channel=0))
    return len(rows)


def read_log(path: Path, dbc: Path | LoadedDatabase, signal_map: Path | SignalMap) -> SignalSet:
    """Decoded torque and speed of a log, through the service's ingest (``open_log`` + ``load_signals``)."""
    db = dbc if isinstance(dbc, LoadedDatabase) else load_database(dbc)
    smap = signal_map if isinstance(signal_map, SignalMap) else load_signal_map(signal_map)
    with open_log(path) as reader:
        signals, _ = load_signals(reader, db, smap, require=CHANNELS)
    return signals
