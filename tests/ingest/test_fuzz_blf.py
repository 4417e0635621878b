"""Broken BLF files: each gives a typed error or a salvage with a report, in bounded time.

Every case runs in a worker thread with a deadline, so a hang fails the test instead of
stalling the suite. The corpus is generated from a fixed seed.
"""

from __future__ import annotations

import io
import struct
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.errors import AppError, LogFormatError, TruncatedLogError, UnsupportedFormatError
from app.ingest.frames import FrameChunk, IngestReport
from app.ingest.readers import open_log
from tests.ingest.test_readers_blf import blf_file, can_msg, obj

DEADLINE_S = 30.0  # generous: a cold numba cache compiles the fallback walker once (~5 s)


@dataclass
class Outcome:
    chunk: FrameChunk | None = None
    report: IngestReport | None = None
    error: AppError | None = None


def run_bounded(data: bytes, *, fmt: str | None = None, strict: bool = False, name: Path | None = None) -> Outcome:
    """Read ``data`` fully in a thread; fail on a hang or on any non-AppError exception."""
    out = Outcome()
    crash: list[BaseException] = []

    def work() -> None:
        try:
            src = name if name is not None else io.BytesIO(data)
            with open_log(src, fmt=fmt, strict=strict, chunk_frames=97) as log:
                out.chunk = FrameChunk.concat(log.chunks())
                out.report = log.report
        except AppError as exc:
            out.error = exc
        except BaseException as exc:  # anything else is the failure under test
            crash.append(exc)

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(DEADLINE_S)
    assert not worker.is_alive(), f"reader still running after {DEADLINE_S} s: it hangs"
    assert not crash, f"foreign exception escaped: {crash[0]!r}"
    assert (out.error is None) != (out.chunk is None)
    return out


N_FRAMES = 400


def base_objects() -> list[bytes]:
    rng = np.random.default_rng(2024)
    return [obj(1, can_msg(1 + i % 2, int(rng.integers(0, 0x7FF)), rng.integers(0, 256, 8, np.uint8).tobytes()),
                i * 1_000_000) for i in range(N_FRAMES)]


BASE = blf_file(base_objects(), container_bytes=3000)  # 7 compressed containers
REFERENCE = run_bounded(BASE).chunk
assert REFERENCE is not None and len(REFERENCE) == N_FRAMES


def container_offsets(data: bytes) -> list[int]:
    offs, pos = [], 144
    while pos + 16 <= len(data):
        size = struct.unpack_from("<L", data, pos + 8)[0]
        offs.append(pos)
        pos += size + size % 4
    return offs


CONTAINERS = container_offsets(BASE)


def is_prefix(chunk: FrameChunk, ref: FrameChunk) -> bool:
    n = len(chunk)
    return all((getattr(chunk, c) == getattr(ref, c)[:n]).all() for c in ("t_ns", "channel", "arb_id", "dlc", "data"))


def kinds(out: Outcome) -> set[str]:
    assert out.report is not None
    return {i.kind for i in out.report.issues}


TRUNCATIONS = sorted({1, 3, 4, 50, 143, 144, 150, 159, 160, 176, *range(181, len(BASE), 211), len(BASE) - 1,
                      *(o + 16 for o in CONTAINERS), *(o + 40 for o in CONTAINERS)})


@pytest.mark.parametrize("cut", TRUNCATIONS)
def test_truncated_blf_salvages_a_prefix(cut: int) -> None:
    out = run_bounded(BASE[:cut])
    if cut < 144 or out.error is not None:
        # nothing salvageable: only the header (or less) is left; below 4 bytes not even the signature
        assert isinstance(out.error, LogFormatError | UnsupportedFormatError if cut < 4 else LogFormatError), out.error
        assert cut < CONTAINERS[0] + 16 + 100
        return
    assert out.chunk is not None and is_prefix(out.chunk, REFERENCE)
    if cut > CONTAINERS[0]:
        assert "truncated" in kinds(out)
        issue = next(i for i in out.report.issues if i.kind == "truncated")  # type: ignore[union-attr]
        assert issue.offset is not None and issue.offset <= cut


@pytest.mark.parametrize("cut", [TRUNCATIONS[len(TRUNCATIONS) // 2], len(BASE) - 5])
def test_truncated_blf_strict_names_the_offset(cut: int) -> None:
    out = run_bounded(BASE[:cut], strict=True)
    assert isinstance(out.error, TruncatedLogError)
    assert "byte offset" in str(out.error)


def _with_bad_object(bad: bytes) -> bytes:
    objs = base_objects()
    objs.insert(200, bad)
    return blf_file(objs, container_bytes=3000)


BAD_OBJECTS = {
    "size-0": struct.pack("<4sHHLL", b"LOBJ", 32, 1, 0, 1) + bytes(32),
    "size-below-header": struct.pack("<4sHHLL", b"LOBJ", 32, 1, 20, 1) + bytes(32),
    "size-huge": struct.pack("<4sHHLL", b"LOBJ", 32, 1, 0x7FFFFFF0, 1) + bytes(32),
    "size-plausible-but-wrong": struct.pack("<4sHHLL", b"LOBJ", 32, 1, 60, 86) + bytes(28),
    "unknown-type-oversized": struct.pack("<4sHHLL", b"LOBJ", 32, 1, 900_000, 4242) + bytes(40),
    "header-version-7": struct.pack("<4sHHLL", b"LOBJ", 32, 7, 48, 1) + bytes(32),
    "garbage": bytes(range(7, 80)),
    "bad-signature": b"LOBX" + obj(1, can_msg(1, 5, b"x"), 0)[4:],
    "timestamp-beyond-int64": obj(1, can_msg(1, 5, b"x"), 2**64 - 1),
    "fd-valid-bytes-200": obj(100, struct.pack("<HBBLLBBB5x", 1, 0, 15, 7, 0, 0, 1, 200) + bytes(64), 0),
}


@pytest.mark.parametrize("case", sorted(BAD_OBJECTS))
def test_bad_inner_object_is_skipped_and_reported(case: str) -> None:
    data = _with_bad_object(BAD_OBJECTS[case])
    out = run_bounded(data)
    assert out.chunk is not None and out.report is not None
    damage = [i for i in out.report.issues if i.kind != "time_backwards"]
    assert damage, "the damage must be reported"
    assert all(i.offset is not None for i in damage)
    # everything before the bad object survives; at most a few neighbours are lost
    assert is_prefix(out.chunk.select(np.arange(len(out.chunk)) < 200), REFERENCE)
    assert len(out.chunk) >= N_FRAMES - 3
    strict = run_bounded(data, strict=True)
    assert isinstance(strict.error, LogFormatError) and "byte offset" in str(strict.error)


def test_corrupt_zlib_container_reported_with_its_offset() -> None:
    data = bytearray(BASE)
    target = CONTAINERS[2]
    data[target + 32 + 40: target + 32 + 60] = bytes(20)  # inside the deflate stream
    out = run_bounded(bytes(data))
    assert out.chunk is not None and out.report is not None
    corrupt = [i for i in out.report.issues if i.kind == "corrupt_zlib"]
    assert len(corrupt) == 1 and corrupt[0].offset == target
    # containers before and after are intact: reading resumed at the next container
    assert len(out.chunk) > N_FRAMES * 0.6
    assert out.chunk.t_ns[-1] == REFERENCE.t_ns[-1]
    strict = run_bounded(bytes(data), strict=True)
    assert isinstance(strict.error, LogFormatError) and str(target) in str(strict.error)


def test_bad_container_signature_and_size_resync() -> None:
    data = bytearray(BASE)
    data[CONTAINERS[1]:CONTAINERS[1] + 4] = b"XXXX"
    data[CONTAINERS[4] + 8:CONTAINERS[4] + 12] = struct.pack("<L", 0)  # container size 0
    out = run_bounded(bytes(data))
    assert out.chunk is not None
    assert "bad_signature" in kinds(out)
    assert out.chunk.t_ns[-1] == REFERENCE.t_ns[-1]


def test_header_only_and_empty() -> None:
    header_only = blf_file([])
    out = run_bounded(header_only)
    assert out.chunk is not None and len(out.chunk) == 0 and out.report is not None and out.report.ok
    empty = run_bounded(b"")
    assert isinstance(empty.error, LogFormatError) and "empty log" in str(empty.error)


def test_random_bytes() -> None:
    rng = np.random.default_rng(99)
    junk = rng.integers(0, 256, 50_000, np.uint8).tobytes()
    assert isinstance(run_bounded(junk).error, UnsupportedFormatError)
    forced = run_bounded(junk, fmt="blf")
    assert isinstance(forced.error, LogFormatError)
    after_header = run_bounded(BASE[:144] + junk)
    assert isinstance(after_header.error, LogFormatError) or after_header.chunk is not None


def test_wrong_suffix_is_read_by_content(tmp_path: Path) -> None:
    path = tmp_path / "actually_blf.asc"
    path.write_bytes(BASE)
    out = run_bounded(b"", name=path)
    assert out.chunk is not None and len(out.chunk) == N_FRAMES


def _mutated(base: bytes, rng: np.random.Generator) -> tuple[bytes, int]:
    """``base`` with 1..11 random bytes past the file header changed, and the first changed position."""
    data = bytearray(base)
    positions = rng.integers(144, len(data), int(rng.integers(1, 12)))
    for pos in positions:
        data[int(pos)] = int(rng.integers(0, 256))
    return bytes(data), int(positions.min())


@pytest.mark.parametrize("seed", range(40))
def test_mutations(seed: int) -> None:
    """Bytes changed past the header: always a salvage (never a refusal), every frame of the containers before
    the first changed byte kept as it was, frames counted in the report, and lost frames reported as damage."""
    rng = np.random.default_rng(seed)
    compressed = _mutated(BASE, rng)
    uncompressed = blf_file(base_objects(), compress=False, container_bytes=5000)
    mutated_plain = _mutated(uncompressed, rng)
    for original, (blob, first) in ((BASE, compressed), (uncompressed, mutated_plain)):
        out = run_bounded(blob)
        assert out.chunk is not None and out.report is not None, out.error
        assert len(out.chunk) <= N_FRAMES + 12 and out.report.frames == len(out.chunk)
        before = [o for o in container_offsets(original) if o <= first][1:]  # starts of the containers after one
        if before:  # the containers before the damaged one, read from the undamaged file
            intact = run_bounded(original[:before[-1]]).chunk
            assert intact is not None and len(out.chunk) >= len(intact) > 0
            assert is_prefix(out.chunk.select(np.arange(len(out.chunk)) < len(intact)), intact)
        if len(out.chunk) < N_FRAMES:
            assert [i for i in out.report.issues if i.kind != "time_backwards"], "lost frames must be reported"


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=3000))
def test_arbitrary_bytes_after_a_blf_header(payload: bytes) -> None:
    run_bounded(BASE[:144] + payload)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(min_size=0, max_size=2000),
       st.sampled_from([None, "blf", "asc", "candump", "trc", "gvret_csv", "mf4", "tcu", "analyser_tsv",
                        "serial_dump"]))
def test_arbitrary_bytes_any_reader(payload: bytes, fmt: str | None) -> None:
    run_bounded(payload, fmt=fmt)


@pytest.mark.parametrize(("field", "value"), [(4, 0), (4, 0xFFFFFFFF), (4, 100_000), (16, 2**63), (42, 13)],
                         ids=["header-size-0", "header-size-max", "header-size-100k", "file-size-huge", "bad-date"])
def test_damaged_file_header_fields(field: int, value: int) -> None:
    data = bytearray(BASE)
    fmt = "<Q" if field == 16 else "<H" if field == 42 else "<L"  # file size u64, SYSTEMTIME month u16
    struct.pack_into(fmt, data, field, value)
    out = run_bounded(bytes(data))
    assert out.chunk is not None and len(out.chunk) == N_FRAMES, out.error
    assert out.report is not None
    if field == 4:
        assert [i.kind for i in out.report.issues] == ["bad_header"]
    elif field == 16:
        assert [i.kind for i in out.report.issues] == ["truncated"]  # the header promises more than the file has
    else:
        assert out.report.ok
