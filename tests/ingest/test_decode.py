"""Vectorized decoder on crafted databases: layouts, FD, floats, ID matching, short frames, NA values, muxes."""

from __future__ import annotations

import struct

import cantools
import numpy as np
import pytest

from app.ingest.decode import DecodedMessage, VectorDecoder, is_na_label
from app.ingest.frames import FrameChunk, FrameFlag
from tests.conftest import shared_file

DBC = '''VERSION ""
NS_ :
BS_:
BU_: A
BO_ 256 Std: 8 A
 SG_ LeU : 0|12@1+ (0.5,-10) [0|0] "rpm" A
 SG_ LeS : 12|13@1- (1,0) [0|0] "" A
 SG_ BeS : 39|16@0- (0.1,0) [0|0] "Nm" A
 SG_ Bit : 63|1@0+ (1,0) [0|0] "" A
BO_ 2147484672 Ext: 8 A
 SG_ Whole : 0|64@1+ (1,0) [0|0] "" A
BO_ 512 Fd: 64 A
 SG_ F32 : 0|32@1- (1,0) [0|0] "" A
 SG_ Be48 : 455|48@0+ (1,0) [0|0] "" A
 SG_ F64 : 64|64@1- (2,1) [0|0] "" A
BO_ 768 Na: 8 A
 SG_ Speed : 0|16@1- (0.5,0) [0|0] "rpm" A
 SG_ State : 16|3@1+ (1,0) [0|0] "" A
SIG_VALTYPE_ 512 F32 : 1;
SIG_VALTYPE_ 512 F64 : 2;
VAL_ 768 Speed -32768 "SNA" ;
VAL_ 768 State 0 "Init" 1 "Run" 2 "No_Error" 7 "Signal not available" ;
'''


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return cantools.database.load_string(DBC, database_format="dbc")


def chunk_of(frames: list[tuple[int, bytes, int]], width: int = 8, channel: int = 0) -> FrameChunk:
    n = len(frames)
    data = np.zeros((n, width), np.uint8)
    for i, (_, payload, _) in enumerate(frames):
        data[i, : len(payload)] = np.frombuffer(payload, np.uint8)
    return FrameChunk(np.arange(n, dtype=np.int64) * 1000, np.full(n, channel, np.int16),
                      np.array([f[0] for f in frames], np.uint32), np.array([f[2] for f in frames], np.uint8),
                      np.array([len(f[1]) for f in frames], np.uint8), data)


def test_layouts_match_cantools(db: cantools.database.can.Database) -> None:
    rng = np.random.default_rng(3)
    payloads = [bytes(rng.integers(0, 256, 8, dtype=np.uint8)) for _ in range(200)] + [b"\xff" * 8, b"\x00" * 8]
    out = VectorDecoder(db).decode(chunk_of([(256, p, 0) for p in payloads]))["Std"]
    assert len(out) == len(payloads)
    for i, p in enumerate(payloads):
        want = db.decode_message(256, p, decode_choices=False)
        assert {k: float(v) for k, v in want.items()} == {k: float(v[i]) for k, v in out.signals.items()}


def test_extended_id_and_flags(db: cantools.database.can.Database) -> None:
    payload = bytes(range(1, 9))
    frames = [(1024, payload, FrameFlag.EXTENDED), (1024, payload, 0), (256, payload, FrameFlag.EXTENDED),
              (256, payload, FrameFlag.ERROR), (256, b"", FrameFlag.REMOTE), (256, payload, 0), (999, payload, 0)]
    out = VectorDecoder(db).decode(chunk_of(frames))
    assert set(out) == {"Ext", "Std"}
    assert out["Ext"].is_extended and out["Ext"].t_ns.tolist() == [0]
    assert out["Ext"].signals["Whole"][0] == float(int.from_bytes(payload, "little"))
    assert out["Std"].t_ns.tolist() == [5000]  # only the standard-ID data frame


def test_fd_float_and_wide_big_endian(db: cantools.database.can.Database) -> None:
    rng = np.random.default_rng(5)
    payloads = [bytes(rng.integers(0, 256, 64, dtype=np.uint8)) for _ in range(50)]
    payloads[0] = struct.pack("<f", 1.5) + bytes(4) + struct.pack("<d", -2.25) + bytes(48)
    out = VectorDecoder(db, na_to_nan=False).decode(chunk_of([(512, p, FrameFlag.FD) for p in payloads], 64))["Fd"]
    assert out.signals["F32"][0] == 1.5 and out.signals["F64"][0] == -2.25 * 2 + 1
    for i, p in enumerate(payloads):
        want = db.decode_message(512, p, decode_choices=False)
        for k, v in want.items():
            got = out.signals[k][i]
            assert (np.isnan(got) and np.isnan(v)) or got == v, (k, p.hex())


def test_short_frames_excluded_or_partial(db: cantools.database.can.Database) -> None:
    frames = [(256, bytes(8), 0), (256, b"\x01\x02\x03", 0), (256, bytes(range(8)) + b"", 0)]
    out = VectorDecoder(db).decode(chunk_of(frames))["Std"]
    assert out.errors == {"short_frame": 1} and out.t_ns.tolist() == [0, 2000]
    part = VectorDecoder(db, allow_truncated=True).decode(chunk_of(frames))["Std"]
    assert len(part) == 3 and part.errors == {}
    want = db.decode_message(256, b"\x01\x02\x03", decode_choices=False, allow_truncated=True)
    assert set(want) == {"LeU"}  # LeS needs bit 24, the fourth byte
    assert part.is_present("LeU")[1] and not part.is_present("LeS")[1] and np.isnan(part.signals["BeS"][1])
    assert part.signals["LeU"][1] == want["LeU"]


def test_na_labels_become_nan(db: cantools.database.can.Database) -> None:
    frames = [(768, struct.pack("<hB", -32768, 0) + bytes(5), 0), (768, struct.pack("<hB", 100, 1) + bytes(5), 0),
              (768, struct.pack("<hB", 3, 2) + bytes(5), 0), (768, struct.pack("<hB", 3, 7) + bytes(5), 0)]
    out = VectorDecoder(db).decode(chunk_of(frames))["Na"]
    assert np.isnan(out.signals["Speed"][0]) and out.signals["Speed"][1] == 50.0
    np.testing.assert_array_equal(out.signals["State"], [np.nan, 1, 2, np.nan])
    raw = VectorDecoder(db, na_to_nan=False).decode(chunk_of(frames))["Na"]
    assert raw.signals["Speed"][0] == -16384.0 and raw.signals["State"].tolist() == [0, 1, 2, 7]
    custom = VectorDecoder(db, na_labels=("run",)).decode(chunk_of(frames))["Na"]
    np.testing.assert_array_equal(custom.signals["State"], [0, np.nan, 2, 7])


@pytest.mark.parametrize(("label", "na"), [
    ("SNA", True), ("sna", True), ("DI_TORQUE_SNA", True), ("Invalid", True), ("Error", True), ("INIT", True),
    ("N/A", True), ("Signal not available", True), ("not available", True), ("No_Error", False),
    ("Running", False), ("Errorless", False), ("SNA_COUNTER_OK", False), ("ERROR_ACTIVE", False),
])
def test_is_na_label(label: str, na: bool) -> None:
    assert is_na_label(label) is na


def test_extended_multiplexing_matches_cantools() -> None:
    path = shared_file("cantools-testfiles", "dbc", "issue_184_extended_mux_cascaded.dbc")
    db = cantools.database.load_file(str(path))
    msg = db.messages[0]
    rng = np.random.default_rng(11)
    payloads = [bytes(rng.integers(0, 256, msg.length, dtype=np.uint8)) for _ in range(400)]
    payloads += [bytes([v]) + bytes(msg.length - 1) for v in range(256)]
    flag = FrameFlag.EXTENDED if msg.is_extended_frame else 0
    out = VectorDecoder(db, na_to_nan=False).decode(chunk_of([(msg.frame_id, p, flag) for p in payloads]))[msg.name]
    kept = set(out.t_ns.tolist())
    row = {t: i for i, t in enumerate(out.t_ns.tolist())}
    bad = 0
    for i, p in enumerate(payloads):
        try:
            want = db.decode_message(msg.frame_id, p, decode_choices=False, force_extended_id=msg.is_extended_frame)
        except Exception:
            bad += 1
            assert i * 1000 not in kept
            continue
        r = row[i * 1000]
        got = {k: float(v[r]) for k, v in out.signals.items() if out.is_present(k)[r]}
        assert got == {k: float(v) for k, v in want.items()}
    assert bad == out.errors.get("unknown_mux", 0) and bad > 0


def test_concat_and_channels(db: cantools.database.can.Database) -> None:
    dec = VectorDecoder(db, messages=["Std"])
    a = dec.decode(chunk_of([(256, bytes(8), 0), (768, bytes(8), 0)], channel=0))
    b = dec.decode(chunk_of([(256, b"\x01" * 8, 0), (256, b"\x01", 0)], channel=3))
    assert set(a) == {"Std"}
    joined = DecodedMessage.concat([a["Std"], b["Std"]])
    assert joined.channel.tolist() == [0, 3] and joined.errors == {"short_frame": 1}
    assert dec.labels("Na")["State"][7] == "Signal not available"


def test_empty_chunk(db: cantools.database.can.Database) -> None:
    assert VectorDecoder(db).decode(FrameChunk.empty()) == {}
