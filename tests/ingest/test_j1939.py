"""J1939 databases: frames match messages by PGN; the report says why frames are unknown.

The real-file test decodes a CANedge MF4 with the CSS Electronics J1939 demo DBC (whose
IDs carry source address 0xFE while the truck sends from 0x00) and compares with asammdf's
``extract_bus_logging`` on the same file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.ingest.database import load_database
from app.ingest.decode import VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.j1939 import pgn
from app.ingest.readers import open_log
from app.ingest.stats import DecodeReport, StatsAccumulator
from tests.conftest import shared_file

CSS = ("css-electronics-mf4", "examples", "data-processing")

DBC = """VERSION ""

NS_ :

BS_:

BU_: ECU

BO_ 2364540158 EEC1: 8 ECU
 SG_ EngineSpeed : 24|16@1+ (0.125,0) [0|8031.875] "rpm" ECU

BO_ 2348810494 TSC1: 8 ECU
 SG_ RequestedTorque : 24|8@1+ (1,-125) [-125|125] "%" ECU

BO_ 1024 Plain: 8 ECU
 SG_ Value : 0|8@1+ (1,0) [0|255] "" ECU

BA_DEF_  "ProtocolType" STRING ;
BA_DEF_DEF_  "ProtocolType" "";
BA_ "ProtocolType" "J1939";
"""
# EEC1: PGN 0xF004 (PDU2, PF 240): the DBC's ID has priority 3, source 0xFE
# TSC1: PGN 0x0000 (PDU1, PF 0): the DBC's ID 0x0C0000FE has destination 0x00, source 0xFE


def _frames(ids: list[int], payloads: list[bytes], extended: bool = True) -> FrameChunk:
    n = len(ids)
    data = np.frombuffer(b"".join(p.ljust(8, b"\0") for p in payloads), np.uint8).reshape(n, 8).copy()
    flags = np.full(n, int(FrameFlag.EXTENDED) if extended else 0, np.uint8)
    return FrameChunk(np.arange(n, dtype=np.int64) * 10_000_000, np.zeros(n, np.int16), np.array(ids, np.uint32),
                      flags, np.full(n, 8, np.uint8), data)


def _db(tmp_path: Path, text: str = DBC) -> object:
    path = tmp_path / "j1939.dbc"
    path.write_text(text)
    return load_database(path)


def test_pgn_masks_priority_source_and_pdu1_destination() -> None:
    assert pgn(0x0CF00400) == pgn(0x18F004FE) == 0xF004  # PDU2: PS is part of the PGN
    assert pgn(0x0C000003) == pgn(0x18002A17) == 0x0000  # PDU1: PS is the destination address
    assert pgn(0x18FEF100) == 0xFEF1 and pgn(0x18FEF200) != pgn(0x18FEF100)
    assert pgn(0x18EA0000) == pgn(0x18EAFF00) == 0xEA00


def test_frames_match_by_pgn_with_any_priority_source_and_destination(tmp_path: Path) -> None:
    db = _db(tmp_path)
    ids = [0x0CF00400, 0x18F00417, 0x0CF004FE, 0x0C000003, 0x0C0A2A00, 0x18FEF100, 0x400, 0x0CF10400]
    payloads = [bytes([0, 0, 0, 0x40, 0x1F]), bytes([0, 0, 0, 0x80, 0x0C]), bytes([0, 0, 0, 0, 0]),
                bytes([0, 0, 0, 200]), bytes([0, 0, 0, 10]), b"", bytes([7]), b""]
    chunk = _frames(ids, payloads)
    chunk = FrameChunk(chunk.t_ns, chunk.channel, chunk.arb_id,
                       np.where(chunk.arb_id == 0x400, 0, chunk.flags).astype(np.uint8), chunk.dlc, chunk.data)
    out = VectorDecoder(db.db).decode(chunk)
    eec1 = out["EEC1"]
    assert eec1.t_ns.tolist() == [0, 10_000_000, 20_000_000]  # three sources, in log order
    assert eec1.signals["EngineSpeed"].tolist() == [0x1F40 * 0.125, 0x0C80 * 0.125, 0.0]
    tsc1 = out["TSC1"]  # destination 0x03 here, the DBC's ID says 0x00; 0x0C0A2A00 is PGN 0x0A00: not TSC1
    assert tsc1.t_ns.tolist() == [30_000_000] and tsc1.signals["RequestedTorque"].tolist() == [75.0]
    assert out["Plain"].signals["Value"].tolist() == [7.0]
    assert set(out) == {"EEC1", "TSC1", "Plain"}
    stats = StatsAccumulator(db.db)
    stats.add_chunk(chunk)
    report = stats.fill(DecodeReport())
    assert report.frames_unknown_id == 3 and report.unknown_hint == ""
    named = {(s.arb_id, s.message) for s in report.ids}
    assert (0x18F00417, "EEC1") in named and (0x0C000003, "TSC1") in named and (0x0C0A2A00, None) in named


def test_without_the_j1939_declaration_ids_match_exactly_and_the_report_says_why(tmp_path: Path) -> None:
    db = _db(tmp_path, DBC.replace('BA_ "ProtocolType" "J1939";\n', ""))
    chunk = _frames([0x0CF00400] * 6 + [0x8CF004FE & 0x1FFFFFFF], [bytes([0, 0, 0, 0x40, 0x1F])] * 7)
    out = VectorDecoder(db.db).decode(chunk)
    assert len(out["EEC1"]) == 1  # only the exact ID
    stats = StatsAccumulator(db.db)
    stats.add_chunk(chunk)
    report = stats.fill(DecodeReport())
    assert report.frames_unknown_id == 6
    assert report.unknown_hint.startswith("6 of 7 frames (86 %) have IDs the database does not define; 6 of them "
                                          "carry the J1939 PGN of a database message (e.g. EEC1)")
    assert "does not declare J1939" in report.unknown_hint


def test_j1939_database_and_foreign_log_says_ids_match_by_pgn(tmp_path: Path) -> None:
    db = _db(tmp_path)
    stats = StatsAccumulator(db.db)
    stats.add_chunk(_frames([0x18FEF100, 0x18FEF200, 0x18FEF100], [b""] * 3))
    report = stats.fill(DecodeReport())
    assert report.frames_unknown_id == 3
    assert "the database is J1939, so IDs match by PGN" in report.unknown_hint
    assert "none of the 2 unknown IDs carries a PGN it defines" in report.unknown_hint


def test_canedge_mf4_decodes_like_asammdf_extract_bus_logging() -> None:
    asammdf = pytest.importorskip("asammdf")
    log = shared_file(*CSS, "LOG", "FCBF0606", "00003482", "00000001-60B621D9.MF4")
    dbc = shared_file(*CSS, "dbc_files", "CSS-Electronics-SAE-J1939-DEMO.dbc")
    db = load_database(dbc)
    decoder = VectorDecoder(db.db)
    with open_log(log) as reader:
        parts = [decoder.decode(c) for c in reader.chunks()]
    ours = {name: [p[name] for p in parts if name in p] for name in ("EEC1", "CCVS1")}
    ref = asammdf.MDF(str(log)).extract_bus_logging({"CAN": [(str(dbc), 0)]})
    peak = {}
    for message, signal in (("EEC1", "EngineSpeed"), ("CCVS1", "WheelBasedVehicleSpeed")):
        theirs = ref.get(signal)
        t = np.concatenate([d.t_ns for d in ours[message]]) / 1e9
        v = np.concatenate([d.signals[signal] for d in ours[message]])
        assert len(v) == len(theirs.samples) > 100
        np.testing.assert_array_equal(v, theirs.samples.astype(np.float64))
        np.testing.assert_allclose(t, theirs.timestamps, rtol=0, atol=1e-6)
        peak[signal] = (len(v), float(np.nanmax(v)))
    # the demo truck stands with the engine off (both signals 0): the match is in which frames and when
    assert peak == {"EngineSpeed": (577, 0.0), "WheelBasedVehicleSpeed": (184, 0.0)}
