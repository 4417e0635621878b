"""The vectorized decoder equals cantools' ``decode_message(..., decode_choices=False)`` exactly.

For every database in cantools' own test files that cantools loads, hypothesis draws payload
bytes for a batch of frames of every message (plus frames one byte short and frames with
excess bytes) and each decoded value is compared bit for bit with cantools' result for the
same frame; frames cantools refuses must be exactly the frames the decoder leaves out.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import cantools
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.ingest.decode import DecodedMessage, VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag
from tests.conftest import sample_files

TESTFILES = "cantools-testfiles"  # tests/data holds two of them, ../shared/data all
FRAMES_PER_MESSAGE = 6


def _loadable() -> list[Path]:
    out = []
    for path in sample_files(TESTFILES, "*/*"):
        try:
            db = cantools.database.load_file(str(path))
        except Exception:  # files that must fail are covered by test_database
            continue
        if isinstance(db, cantools.database.can.Database) and db.messages:
            out.append(path)
    return out


LOADABLE = _loadable()


def _same(expected: float, got: float) -> bool:
    if math.isnan(expected) or math.isnan(got):
        return math.isnan(expected) and math.isnan(got)
    return struct.pack("<d", expected) == struct.pack("<d", got)


def build_chunk(db: cantools.database.can.Database, blob: bytes, fill: int | None, truncate: bool,
                ) -> tuple[FrameChunk, list[tuple[int, bool, bytes]]]:
    """Frames of every message: full length, with excess bytes, and one byte short."""
    frames: list[tuple[int, bool, bytes]] = []
    pos = 0
    for msg in db.messages:
        if msg.is_container:
            continue
        for k in range(FRAMES_PER_MESSAGE):
            n = msg.length
            if k == FRAMES_PER_MESSAGE - 1 and truncate and n > 0:
                n -= 1
            elif k == FRAMES_PER_MESSAGE - 2 and n < 8:
                n = 8  # excess bytes are ignored by cantools (allow_excess)
            if fill is not None and k == 0:
                payload = bytes([fill]) * n
            else:
                payload = bytes(blob[(pos + i) % len(blob)] for i in range(n))
                pos += n + 1
            frames.append((msg.frame_id, bool(msg.is_extended_frame), payload))
    width = max(8, max((len(p) for _, _, p in frames), default=8))
    width = 64 if width > 8 else 8
    count = len(frames)
    data = np.zeros((count, width), np.uint8)
    flags = np.zeros(count, np.uint8)
    for i, (_, ext, payload) in enumerate(frames):
        data[i, : len(payload)] = np.frombuffer(payload, np.uint8)
        flags[i] = (FrameFlag.EXTENDED if ext else 0) | (FrameFlag.FD if len(payload) > 8 else 0)
    chunk = FrameChunk(
        np.arange(count, dtype=np.int64), np.zeros(count, np.int16),
        np.array([f[0] for f in frames], np.uint32), flags,
        np.array([len(f[2]) for f in frames], np.uint8), data,
    )
    return chunk, frames


def check_equal(db: cantools.database.can.Database, chunk: FrameChunk, frames: list[tuple[int, bool, bytes]],
                allow_truncated: bool) -> None:
    decoder = VectorDecoder(db, na_to_nan=False, allow_truncated=allow_truncated)
    result = decoder.decode(chunk)
    by_key: dict[tuple[int, bool], DecodedMessage] = {(m.frame_id, m.is_extended): m for m in result.values()}
    rows: dict[int, tuple[DecodedMessage, int]] = {}
    for m in result.values():
        for r, t in enumerate(m.t_ns.tolist()):
            rows[t] = (m, r)
    for i, (frame_id, ext, payload) in enumerate(frames):
        try:
            expected = db.decode_message(frame_id, payload, decode_choices=False,
                                         allow_truncated=allow_truncated, force_extended_id=ext)
        except Exception:
            assert i not in rows, f"frame {i} id 0x{frame_id:x} {payload.hex()}: cantools raises, decoder kept it"
            assert sum(by_key[(frame_id, ext)].errors.values()) > 0
            continue
        assert i in rows, f"frame {i} id 0x{frame_id:x} {payload.hex()}: decoder dropped a frame cantools decodes"
        msg, r = rows[i]
        assert isinstance(expected, dict)
        for name, values in msg.signals.items():
            got = float(values[r])
            if name not in expected:
                assert not msg.is_present(name)[r] and math.isnan(got), f"{msg.name}.{name} should be absent"
                continue
            assert msg.is_present(name)[r], f"{msg.name}.{name} present in cantools but flagged absent"
            want = float(expected[name])
            assert _same(want, got), f"{msg.name}.{name} frame {payload.hex()}: cantools {want!r}, decoder {got!r}"


@pytest.mark.skipif(not LOADABLE, reason=f"cantools test files not found under {TESTFILES}")
@pytest.mark.parametrize("path", LOADABLE, ids=lambda p: f"{p.parent.name}/{p.name}")
@settings(max_examples=8, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(blob=st.binary(min_size=97, max_size=97), fill=st.sampled_from([None, 0x00, 0xFF, 0x80, 0x7F]),
       allow_truncated=st.booleans())
def test_decoder_equals_cantools(path: Path, blob: bytes, fill: int | None, allow_truncated: bool) -> None:
    db = cantools.database.load_file(str(path))
    chunk, frames = build_chunk(db, blob, fill, truncate=True)
    check_equal(db, chunk, frames, allow_truncated)
