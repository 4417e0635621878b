"""Write the demo drive as a BLF log: simulate, add sensor effects, encode through the DBC.

Channels are routed to DBC messages by the project's signal map (``dbc/lashscope_ev.map.toml``
read in reverse: canonical channel -> message and signal). Each message is sent at the
sample times of its first channel; other signals in the same message are interpolated onto
them, as an ECU packs its latest values. Alive counters (as the ingest recognises them) count
up frame by frame over the DBC's range; ``drops`` frames per message, at positions drawn from
a generator seeded by the message id, are left out as a lossy bus would lose them, so the
counters show gaps. Other signals no channel feeds (status bits) are sent as 0. Frames are
written in time order with python-can's BLF writer.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import can
import numpy as np

from app import atomic
from app.demo.scenario import Channel, Scenario, measured_channels
from app.errors import DatabaseError
from app.ingest.stats import counter_modulus
from app.pipeline import signal_routes
from sim import load_vehicle

DEMO_START_EPOCH_S = 1_718_000_000.0  # fixed absolute start so the same content gives the same file


def encode_blf(path: Path, channels: Mapping[str, Channel], routes: Mapping[str, tuple[str, str]],
               database: object, drops: int = 0, start_epoch_s: float = DEMO_START_EPOCH_S) -> int:
    """Encode ``channels`` into ``path`` (BLF); ``routes`` maps channel -> (message name, signal name).

    Returns the number of frames written (``drops`` per message fewer than were sent). The log starts
    at ``start_epoch_s`` (s since the epoch; fixed by default so the same content gives the same file).
    """
    db = database
    by_message: dict[str, list[str]] = {}
    for ch, (msg, _sig) in routes.items():
        if ch in channels:
            by_message.setdefault(msg, []).append(ch)
    frames: list[tuple[float, int, bool, bytes]] = []
    for msg_name, chans in by_message.items():
        try:
            msg = db.get_message_by_name(msg_name)  # type: ignore[attr-defined]
        except KeyError as exc:
            raise DatabaseError(f"message {msg_name!r} from the signal map is not in the DBC") from exc
        t = channels[chans[0]].t
        cols = {routes[c][1]: np.interp(t, channels[c].t, channels[c].values) for c in chans}
        for s in msg.signals:
            if s.name not in cols:
                modulus = counter_modulus(s)
                cols[s.name] = (np.arange(t.size) % modulus).astype(np.float64) if modulus else np.zeros(t.size)
        names = list(cols)
        values = np.column_stack([cols[n] for n in names])
        lo = np.array([s.minimum if s.minimum is not None else -np.inf for s in (msg.get_signal_by_name(n)
                                                                                  for n in names)])
        hi = np.array([s.maximum if s.maximum is not None else np.inf for s in (msg.get_signal_by_name(n)
                                                                                 for n in names)])
        values = np.clip(values, lo, hi)
        lost = set()
        if drops and t.size > 4 * drops:  # never the first or last frames; deterministic per message id
            rng = np.random.default_rng(int(msg.frame_id))
            lost = set(rng.choice(np.arange(2, t.size - 2), size=drops, replace=False).tolist())
        for k in range(t.size):
            if k in lost:
                continue
            data = msg.encode(dict(zip(names, values[k].tolist(), strict=True)), scaling=True, strict=False)
            frames.append((float(t[k]), int(msg.frame_id), bool(msg.is_extended_frame), bytes(data)))
    frames.sort(key=lambda f: (f[0], f[1]))
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic.atomic_path(path) as tmp, can.BLFWriter(str(tmp)) as writer:
        for ts, arb, ext, data in frames:
            writer.on_message_received(can.Message(timestamp=start_epoch_s + ts, arbitration_id=arb,
                                                   is_extended_id=ext, data=data, channel=0))
    return len(frames)


def build_demo_log(path: Path, dbc: Path, signal_map: Path, scenario: Scenario | None = None,
                   start_epoch_s: float = DEMO_START_EPOCH_S) -> int:
    """Simulate the scripted drive (paper preset truth) and write it to ``path``; returns the frame count."""
    loaded, routes = signal_routes(dbc, signal_map)
    channels = measured_channels(load_vehicle("paper"), scenario)
    return encode_blf(path, channels, routes, loaded.db, drops=(scenario or Scenario()).dropped_frames,
                      start_epoch_s=start_epoch_s)
