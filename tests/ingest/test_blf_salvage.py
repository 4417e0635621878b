"""BLF salvage keeps every intact frame: damage planted in a generated file, kept frames compared exactly.

Each case damages one log container of a generated file (size field inflated or
over/under-declared, signature overwritten, deflate stream corrupted) and compares what
the reader keeps with the frames that are still intact: all of them when only a header
field is damaged, and for a corrupt deflate stream the frames whose objects inflate
completely from the bytes before the damage (none when only the stream's checksum fails:
then no byte of it is trustworthy).
"""

from __future__ import annotations

import struct
import zlib

import numpy as np
import pytest

from app.ingest.frames import FrameChunk
from tests.ingest.test_readers_blf import blf_file, can_msg, obj, read

N = 3000
CONTAINER_BYTES = 8000  # about 166 CAN objects of 48 bytes per container: 19 containers


def _objects() -> list[bytes]:
    rng = np.random.default_rng(1505)
    return [obj(1, can_msg(1 + i % 2, int(rng.integers(0, 0x7FF)), rng.integers(0, 256, 8, np.uint8).tobytes()),
                i * 1_000_000) for i in range(N)]


OBJECTS = _objects()
BASE = blf_file(OBJECTS, container_bytes=CONTAINER_BYTES)
REFERENCE, _ = read(BASE)
assert len(REFERENCE) == N


def _containers(data: bytes) -> list[int]:
    offs, pos = [], 144
    while pos + 16 <= len(data):
        offs.append(pos)
        size = struct.unpack_from("<L", data, pos + 8)[0]
        pos += size + size % 4
    return offs


CONTAINERS = _containers(BASE)
TARGET = CONTAINERS[7]


def _rows(chunk: FrameChunk) -> list[tuple[int, int, int, bytes]]:
    return [(int(chunk.t_ns[i]), int(chunk.channel[i]), int(chunk.arb_id[i]), chunk.data[i, :8].tobytes())
            for i in range(len(chunk))]


def _set_size(data: bytes, at: int, size: int) -> bytes:
    out = bytearray(data)
    out[at + 8:at + 12] = struct.pack("<L", size)
    return bytes(out)


def _size(at: int) -> int:
    return int(struct.unpack_from("<L", BASE, at + 8)[0])


@pytest.mark.parametrize("extra", [1 << 20, (1 << 20) + 3, 5 << 20])
def test_container_size_inflated_by_a_mebibyte_or_more_loses_nothing(extra: int) -> None:
    for target in (TARGET, CONTAINERS[-2]):
        chunk, log = read(_set_size(BASE, target, _size(target) + extra))
        assert _rows(chunk) == _rows(REFERENCE)
        fixed = [i for i in log.report.issues if i.kind == "bad_object_size"]
        assert len(fixed) == 1 and fixed[0].offset == target and fixed[0].frames_lost == 0
        assert not any(i.kind == "truncated" for i in log.report.issues)


@pytest.mark.parametrize("delta", [4, 5, 7, 64, 1000, 4096, -4, -100])
def test_container_size_over_or_under_declared_loses_nothing(delta: int) -> None:
    chunk, log = read(_set_size(BASE, TARGET, _size(TARGET) + delta))
    assert _rows(chunk) == _rows(REFERENCE)
    assert [(i.kind, i.offset, i.frames_lost, i.bytes_lost) for i in log.report.issues] == [
        ("bad_object_size", TARGET, 0, 0)]


def test_damaged_container_signature_is_read_as_a_container() -> None:
    data = bytearray(BASE)
    data[TARGET:TARGET + 4] = b"L0BJ"
    chunk, log = read(bytes(data))
    assert _rows(chunk) == _rows(REFERENCE)
    assert [(i.kind, i.offset, i.frames_lost) for i in log.report.issues] == [("bad_signature", TARGET, 0)]


def _split_by_damage(at: int, damaged: bytes) -> tuple[list[int], list[int]]:
    """Reference frame indices outside the damaged container, and those zlib still vouches for inside it.

    When the damaged stream fails with a decode error, the objects wholly inside what inflates
    from the bytes before the damage are intact; when it inflates and only its checksum fails,
    no byte of it can be trusted.
    """
    starts = np.cumsum([0] + [len(o) for o in OBJECTS])  # object boundaries in the inner byte stream
    k = CONTAINERS.index(TARGET)
    inner_start, inner_next = k * CONTAINER_BYTES, (k + 1) * CONTAINER_BYTES
    outside = [i for i in range(N) if starts[i + 1] <= inner_start or starts[i] >= inner_next]
    try:
        zlib.decompress(damaged[TARGET + 32:TARGET + _size(TARGET)])
    except zlib.error as exc:
        if "incorrect data check" in str(exc):
            return outside, []
    clean = zlib.decompressobj().decompress(BASE[TARGET + 32:at])  # what inflates from the bytes before the damage
    good_end = inner_start + len(clean)
    return outside, [i for i in range(N) if i not in outside and starts[i + 1] <= good_end]


@pytest.mark.parametrize("seed", range(12))
def test_corrupt_deflate_stream_keeps_what_inflates_before_the_damage(seed: int) -> None:
    rng = np.random.default_rng(seed)
    size = _size(TARGET)
    at = TARGET + 32 + int(rng.integers(200, size - 32 - 200))
    data = bytearray(BASE)
    span = int(rng.integers(1, 24))
    data[at:at + span] = rng.integers(0, 256, span, np.uint8).tobytes() if seed % 2 else bytes(span)
    chunk, log = read(bytes(data))
    kept, ref = _rows(chunk), _rows(REFERENCE)
    outside, inside = _split_by_damage(at, bytes(data))
    # every frame outside the damaged container is kept; inside it, the intact frames up to the damage,
    # of which the reader drops at most the last two (garbage before zlib detects the damage can chain)
    kept_inside = [r for r in kept if r not in {ref[i] for i in outside}]
    assert [r for r in kept if r not in kept_inside] == [ref[i] for i in outside]
    assert kept_inside == [ref[i] for i in inside][:len(kept_inside)]
    assert len(inside) - 2 <= len(kept_inside) <= len(inside)
    corrupt = [i for i in log.report.issues if i.kind == "corrupt_zlib"]
    assert len(corrupt) == 1 and corrupt[0].offset == TARGET
    lost = N - len(kept)
    issued = sum(i.frames_lost or 0 for i in log.report.issues)
    assert corrupt[0].bytes_lost is not None and corrupt[0].bytes_lost >= 48 * (lost - 2)
    assert abs(issued - lost) <= max(2, lost // 10), (issued, lost)  # estimated from bytes, within 10 %


def test_every_damage_at_once() -> None:
    data = _set_size(BASE, CONTAINERS[2], _size(CONTAINERS[2]) + (2 << 20))
    data = _set_size(data, CONTAINERS[5], _size(CONTAINERS[5]) + 333)
    data = _set_size(data, CONTAINERS[9], _size(CONTAINERS[9]) - 40)
    damaged = bytearray(data)
    damaged[CONTAINERS[12]:CONTAINERS[12] + 4] = b"XXXX"
    chunk, log = read(bytes(damaged))
    assert _rows(chunk) == _rows(REFERENCE)
    assert sorted((i.offset, i.frames_lost) for i in log.report.issues) == [
        (CONTAINERS[2], 0), (CONTAINERS[5], 0), (CONTAINERS[9], 0), (CONTAINERS[12], 0)]
