"""The per-frame path for small live batches equals the vector decoder + signal map, value for value."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.ingest.frames import FrameChunk, FrameFlag
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


@pytest.mark.parametrize("which", ["reference", "drive"])
def test_small_batches_equal_the_vector_path(which: str, tmp_path: Path) -> None:
    if which == "reference":
        dbc, smap = REF_DBC, REF_MAP
    else:
        dbc = drive.write_dbc(tmp_path)
        smap = drive.map_of(dbc)
    source, _ = source_for(dbc, smap)
    assert source.framewise is not None
    ids = sorted({m.frame_id for m in source.decoder.db.messages})
    chunk = _random_chunk(ids, 6000, seed=7)
    small, small_meta = _feed_all(source, chunk, batch=16)  # per-frame path
    big, big_meta = _feed_all(source, chunk, batch=4096)  # vector path
    assert small.keys() == big.keys() and len(small) >= 3
    for name in big:
        np.testing.assert_array_equal(small[name][0], big[name][0], err_msg=name)
        np.testing.assert_array_equal(small[name][1], big[name][1], err_msg=name)  # NaN == NaN here
    assert small_meta == big_meta
    assert big_meta["errors"].get("short_frame", 0) > 0 and big_meta["unknown"]
    if which == "reference":  # its VAL_ tables label "not available" values: they were exercised
        assert any(np.isnan(v).any() for _, v in big.values())
