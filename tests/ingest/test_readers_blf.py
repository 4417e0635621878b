"""BLF reader details on hand-built files: object types python-can's writer never produces.

``blf_file`` and ``obj`` build files byte by byte from the documented layout
(:mod:`app.ingest.readers.blf_layout`); the fuzz tests reuse them.
"""

from __future__ import annotations

import io
import struct
import zlib
from datetime import datetime

import pytest

from app.errors import LogFormatError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import blf as blf_module
from app.ingest.readers import open_log
from tests.conftest import sample_files, sample_path

START = (2024, 3, 2, 5, 14, 30, 15, 250)  # SYSTEMTIME: 2024-03-05 14:30:15.250 (a Tuesday)


def obj(otype: int, payload: bytes, ts: int, *, tflags: int = 2, hver: int = 1) -> bytes:
    """One inner object: base header, v1 or v2 header, payload, ``size % 4`` padding."""
    hsize = 32 if hver == 1 else 40
    size = hsize + len(payload)
    head = struct.pack("<4sHHLL", b"LOBJ", hsize, hver, size, otype)
    if hver == 1:
        head += struct.pack("<LHHQ", tflags, 0, 0, ts)
    else:
        head += struct.pack("<LBxHQQ", tflags, 0, 0, ts, 0)
    return head + payload + b"\0" * (size % 4)


def can_msg(ch: int, ident: int, data: bytes, *, dlc: int | None = None, flags: int = 0) -> bytes:
    return struct.pack("<HBBL8s", ch, flags, len(data) if dlc is None else dlc, ident, data)


def container(inner: bytes, *, compress: bool = True) -> bytes:
    body = zlib.compress(inner) if compress else inner
    size = 32 + len(body)
    return (struct.pack("<4sHHLL", b"LOBJ", 16, 1, size, 10) + struct.pack("<H6xL4x", 2 if compress else 0, len(inner))
            + body + b"\0" * (size % 4))


def blf_file(objects: list[bytes], *, compress: bool = True, container_bytes: int = 128 * 1024) -> bytes:
    """A complete BLF file; the inner byte stream is cut into containers at arbitrary offsets."""
    stream = b"".join(objects)
    body = b"".join(container(stream[i:i + container_bytes], compress=compress)
                    for i in range(0, len(stream), container_bytes))
    header = struct.pack("<4sLBBBBBBBBQQLL8H8H", b"LOGG", 144, 5, 1, 2, 3, 4, 5, 6, 7, 144 + len(body), 0,
                         len(objects), 0, *START, *START)
    return header + b"\0" * (144 - len(header)) + body


def read(data: bytes, **kw: object) -> tuple[FrameChunk, object]:
    with open_log(io.BytesIO(data), **kw) as log:  # type: ignore[arg-type]
        chunk = FrameChunk.concat(log.chunks())
    return chunk, log


def test_header_start_time_is_local_wall_clock() -> None:
    _, log = read(blf_file([obj(1, can_msg(1, 0x100, b"\x01"), 0)]))
    assert log.meta.start_time == datetime(2024, 3, 5, 14, 30, 15, 250000)  # type: ignore[attr-defined]
    assert log.meta.start_clock == "blf_header_local"  # type: ignore[attr-defined]
    assert log.meta.extra["application_id"] == "5"  # type: ignore[attr-defined]


@pytest.mark.parametrize("hver", [1, 2])
def test_timestamp_units_and_header_versions(hver: int) -> None:
    objs = [obj(1, can_msg(1, 0x100, b"\x01\x02"), 12345, tflags=1, hver=hver),  # 10 us units
            obj(86, can_msg(2, 0x80000123, b"\x03") + b"\0" * 8, 999_999_999, tflags=2, hver=hver)]
    chunk, log = read(blf_file(objs))
    assert list(chunk.t_ns) == [123_450_000, 999_999_999]
    assert list(chunk.channel) == [0, 1]
    assert list(chunk.arb_id) == [0x100, 0x123]
    assert list(chunk.flags) == [0, FrameFlag.EXTENDED]
    assert log.report.ok  # type: ignore[attr-defined]


def test_error_and_fd_object_types() -> None:
    fd64 = struct.pack("<BBBBLLLLLLLHBBL", 2, 13, 32, 0, 0x80000042, 0, 0x1000 | 0x2000, 0, 0, 0, 0, 0, 1, 0, 0)
    fd_err = struct.pack("<BBBBHHHBBLLLLLLLHH", 1, 9, 12, 0, 0, 0, 0, 0, 0, 0x77, 0, 0, 0, 0, 0, 0, 0, 0)
    objs = [
        obj(2, struct.pack("<HH", 3, 0), 10),  # CAN_ERROR
        obj(101, fd64 + bytes(range(32)), 20),  # CAN_FD_MESSAGE_64, 32 bytes, BRS, Tx
        obj(104, fd_err + bytes(range(64)), 30),  # CAN_FD_ERROR_64
        obj(100, struct.pack("<HBBLLBBB5x", 1, 0x80, 8, 0x55, 0, 0, 1, 0) + bytes(64), 40),  # FD-channel remote
    ]
    chunk, log = read(blf_file(objs))
    assert log.report.ok  # type: ignore[attr-defined]
    assert list(chunk.flags) == [FrameFlag.ERROR, FrameFlag.FD | FrameFlag.BRS | FrameFlag.EXTENDED | FrameFlag.TX,
                                 FrameFlag.ERROR | FrameFlag.FD, FrameFlag.FD | FrameFlag.REMOTE]
    assert list(chunk.channel) == [2, 1, 0, 0]
    assert list(chunk.dlc) == [0, 32, 12, 8]
    assert bytes(chunk.data[1, :32]) == bytes(range(32)) and not chunk.data[1, 32:].any()
    assert bytes(chunk.data[2, :12]) == bytes(range(12)) and not chunk.data[2, 12:].any()
    assert chunk.arb_id[1] == 0x42 and chunk.arb_id[2] == 0x77


def test_other_objects_are_skipped_and_summarised() -> None:
    objs = [obj(1, can_msg(1, 0x1, b""), 0), obj(96, b"\0" * 40, 1), obj(65, b"\0" * 12, 2), obj(77, b"\0" * 8, 3),
            obj(125, b"\0" * 8, 4), obj(1, can_msg(1, 0x2, b"\x09"), 5)]
    chunk, log = read(blf_file(objs))
    assert list(chunk.arb_id) == [1, 2]
    kinds = {i.kind: i for i in log.report.issues}  # type: ignore[attr-defined]
    assert set(kinds) == {"unknown_object", "data_lost"}
    assert "type 77" in kinds["unknown_object"].message
    assert "GLOBAL_MARKER(96) x1" in log.meta.extra["skipped_objects"]  # type: ignore[attr-defined]
    # informational entries never fail a strict read
    assert len(read(blf_file(objs), strict=True)[0]) == 2


@pytest.mark.parametrize("compress", [True, False])
@pytest.mark.parametrize("cut", [7, 48, 100, 4096])
def test_objects_straddling_containers(compress: bool, cut: int) -> None:
    objs = [obj(1, can_msg(1 + i % 2, i, bytes([i % 256] * (i % 9))), i * 1000) for i in range(500)]
    objs.insert(250, obj(100, struct.pack("<HBBLLBBB5x", 1, 0, 15, 7, 0, 0, 1, 64) + bytes(range(64)), 249_500))
    chunk, log = read(blf_file(objs, compress=compress, container_bytes=cut))
    assert log.report.ok and len(chunk) == 501  # type: ignore[attr-defined]
    assert bytes(chunk.data[250, :64]) == bytes(range(64)) and chunk.dlc[250] == 64
    assert list(chunk.arb_id[:250]) == list(range(250))


def test_stray_signature_inside_a_payload_falls_back_correctly() -> None:
    # "LOBJ" inside CAN data defeats the vectorised chain check; the compiled walk must take over
    objs = [obj(1, can_msg(1, i, b"LOBJLOBJ" if i == 3 else b"\x00"), i) for i in range(10)]
    chunk, log = read(blf_file(objs))
    assert log.report.ok and list(chunk.arb_id) == list(range(10))  # type: ignore[attr-defined]
    assert bytes(chunk.data[3]) == b"LOBJLOBJ"


def test_not_blf_signature() -> None:
    with pytest.raises(LogFormatError, match="not a BLF file"):
        open_log(io.BytesIO(b"LOGX" + bytes(200)), fmt="blf")


def _fd_mix() -> bytes:
    fd64 = struct.pack("<BBBBLLLLLLLHBBL", 2, 13, 32, 0, 0x80000042, 0, 0x1000 | 0x2000, 0, 0, 0, 0, 0, 1, 0, 0)
    objs = [obj(1, can_msg(1, i, bytes([i] * (i % 9)), flags=0x80 if i % 7 == 0 else 0), i * 10, tflags=1 + i % 2)
            for i in range(60)]
    objs += [obj(101, fd64 + bytes(range(32)), 700), obj(2, struct.pack("<HH", 3, 0), 710),
             obj(73, struct.pack("<HHLBBBxLLH2x8s", 2, 0, 0, 0, 0, 8, 0, 0x123, 0, b"abcdefgh"), 720),
             obj(86, can_msg(2, 0x80000001, b"\x01\x02") + b"\0" * 8, 730, hver=2), obj(96, b"\0" * 44, 740)]
    return blf_file(objs, container_bytes=333)


PYCAN_BLF = sample_files("python-can-testdata/test/data", "*.blf")


@pytest.mark.parametrize("name", ["mix", *[p.name for p in PYCAN_BLF]])
def test_vectorised_path_equals_compiled_walk(name: str, monkeypatch: pytest.MonkeyPatch) -> None:
    data = _fd_mix() if name == "mix" else sample_path("python-can-testdata", "test", "data", name).read_bytes()
    fast, fast_log = read(data)
    monkeypatch.setattr(blf_module, "decode_run", lambda buf, start: None)  # force the object-by-object walk
    slow, slow_log = read(data)
    assert fast_log.report.issues == slow_log.report.issues  # type: ignore[attr-defined]
    assert fast_log.meta.extra == slow_log.meta.extra  # type: ignore[attr-defined]
    assert len(fast) == len(slow) > 0
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc"):
        assert (getattr(fast, col) == getattr(slow, col)).all(), col
    assert (fast.data == slow.data[:, : fast.width]).all() and not slow.data[:, fast.width:].any()


@pytest.mark.parametrize("cut", [20, 71, 100, 143])
def test_truncated_file_header_names_one_header_size(cut: int) -> None:
    """Cut inside the 144-byte header, before or after its fixed 72-byte part: the same wording."""
    data = blf_file([obj(1, can_msg(1, 5, b"x"), 0)])[:cut]
    with pytest.raises(LogFormatError) as err:
        read(data)
    assert "the file ends inside its 144-byte header" in str(err.value)
    assert "72" not in str(err.value)
