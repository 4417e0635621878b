"""Live decoding: any batch size gives the same channels, equal to cantools frame by frame + the signal map."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.ingest.database import load_database
from app.ingest.decode import is_na_label
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.signalmap import load_signal_map
from app.live.decoding import source_for
from tests.conftest import REPO
from tests.live import drive

REF_DBC = REPO / "dbc" / "lashscope_ev.dbc"
REF_MAP = REPO / "dbc" / "lashscope_ev.map.toml"


def _random_chunk(ids: list[int], n: int, seed: int) -> FrameChunk:
    rng = np.random.default_rng(seed)
    arb = rng.choice(np.array([*ids, 0x7DF, 0x123], np.uint32), n)
    data = rng.integers(0, 256, (n, 8), dtype=np.uint8)
    # raw values the DBCs label "not available" (0x8000 / 0xFF / 0xFFFF patterns) in a quarter of the rows
    na_rows = rng.random(n) < 0.25
    data[na_rows, 0:2] = [0x00, 0x80]
    data[rng.random(n) < 0.1, 0:2] = 0xFF
    dlc = np.where(rng.random(n) < 0.05, rng.integers(0, 8, n), 8).astype(np.uint8)  # some short frames
    flags = np.where(rng.random(n) < 0.03, FrameFlag.ERROR, 0).astype(np.uint8)
    channel = rng.integers(0, 2, n).astype(np.int16)
    t_ns = np.cumsum(rng.integers(1, 2_000_000, n)).astype(np.int64)
    return FrameChunk(t_ns, channel, arb, flags, dlc, data)


def _feed_all(source, chunk: FrameChunk, batch: int) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict]:
    parts: dict[str, list[tuple[np.ndarray, np.ndarray]]] = {}
    errors: dict[str, int] = {}
    unknown: dict[int, int] = {}
    good = (chunk.flags & (FrameFlag.ERROR | FrameFlag.REMOTE)) == 0
    chunk = chunk.select(good)
    for i in range(0, len(chunk), batch):
        f = source.feed(chunk.select((np.arange(len(chunk)) >= i) & (np.arange(len(chunk)) < i + batch)))
        for name, tv in f.channels.items():
            parts.setdefault(name, []).append(tv)
        for k, v in f.decode_errors.items():
            errors[k] = errors.get(k, 0) + v
        for k, v in zip(f.unknown_ids.tolist(), f.unknown_counts.tolist(), strict=True):
            unknown[k] = unknown.get(k, 0) + v
    return {k: (np.concatenate([p[0] for p in v]), np.concatenate([p[1] for p in v])) for k, v in parts.items()}, \
        {"errors": errors, "unknown": unknown}


def _cantools_channels(source, chunk: FrameChunk, resolved) -> tuple[dict[str, tuple[np.ndarray, np.ndarray]], dict]:
    """The oracle: ``Message.decode`` per frame, "not available" labels -> NaN, the map's gain, offset and bus."""
    t: dict[str, list[float]] = {}
    v: dict[str, list[float]] = {}
    short = 0
    by_id = {r.message.frame_id: r.message for r in resolved.values()}
    for i in range(len(chunk)):
        msg = by_id.get(int(chunk.arb_id[i]))
        if msg is None or chunk.flags[i] & (FrameFlag.ERROR | FrameFlag.REMOTE | FrameFlag.EXTENDED):
            continue
        if int(chunk.dlc[i]) < msg.length:
            short += 1
            continue
        raw = msg.decode(chunk.data[i, :int(chunk.dlc[i])].tobytes(), decode_choices=False, scaling=False)
        for channel, r in resolved.items():
            if r.message is not msg or (r.spec.bus is not None and r.spec.bus != int(chunk.channel[i])):
                continue
            x = raw[r.signal.name]
            na = {k for k, label in (r.signal.choices or {}).items() if is_na_label(str(label))}
            value = float("nan") if x in na else float(r.signal.conversion.raw_to_scaled(x, False))
            if value == value and (r.gain != 1.0 or r.offset != 0.0):
                value = value * r.gain + r.offset
            t.setdefault(channel, []).append(int(chunk.t_ns[i]) / 1e9)
            v.setdefault(channel, []).append(value)
    return {c: (np.asarray(t[c]), np.asarray(v[c])) for c in t}, {"short_frame": short} if short else {}


@pytest.mark.parametrize("which", ["reference", "drive"])
def test_any_batch_size_equals_cantools_per_frame(which: str, tmp_path: Path) -> None:
    if which == "reference":
        dbc, smap = REF_DBC, REF_MAP
    else:
        dbc = drive.write_dbc(tmp_path)
        smap = drive.map_of(dbc)
    source, _ = source_for(dbc, smap)
    resolved = load_signal_map(smap).resolve(load_database(dbc).db)
    ids = sorted({m.frame_id for m in source.decoder.db.messages})
    chunk = _random_chunk(ids, 6000, seed=7)
    small, small_meta = _feed_all(source, chunk, batch=16)  # live: a few frames per batch
    big, big_meta = _feed_all(source, chunk, batch=4096)  # catching up / offline-sized batches
    oracle, oracle_errors = _cantools_channels(source, chunk, resolved)
    assert small.keys() == big.keys() == oracle.keys() and len(small) >= 3
    for name in big:
        for got in (small, big):
            np.testing.assert_array_equal(got[name][0], oracle[name][0], err_msg=name)
            np.testing.assert_array_equal(got[name][1], oracle[name][1], err_msg=name)  # NaN == NaN here
    assert small_meta == big_meta and big_meta["errors"] == oracle_errors
    assert big_meta["errors"].get("short_frame", 0) > 0 and big_meta["unknown"]
    if which == "reference":  # its VAL_ tables label "not available" values: they were exercised
        assert any(np.isnan(v).any() for _, v in big.values())
