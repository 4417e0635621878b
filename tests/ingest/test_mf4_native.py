"""The numpy MF4 reader against asammdf, on the shared CANedge files and asammdf's own layouts, and damaged files.

Every case compares whole frame columns with the reader run through asammdf
(``LASHSCOPE_MF4_NATIVE=false``): the unfinalised, unsorted CANedge originals (VLSD payloads) and
asammdf's re-saves of them (sorted; plain, deflate and transposed deflate data blocks; a DL
list when concatenated). Damaged copies must give a typed error or keep exactly the intact
frames before the damage, with the loss reported.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np
import pytest

from app.errors import LogFormatError, TruncatedLogError
from app.ingest.frames import FrameChunk, IngestReport
from app.ingest.readers import open_log
from app.ingest.readers.mf4_blocks import MdfFile
from tests.conftest import sample_files, shared_file

MF4 = sample_files("css-electronics-mf4", "**/*.MF4")
pytestmark = pytest.mark.skipif(not MF4, reason="CANedge MF4 files not found (set LASHSCOPE_SHARED)")
COLUMNS = ("t_ns", "channel", "arb_id", "flags", "dlc", "data")


def read(path: Path, *, native: bool = True, strict: bool = False) -> tuple[FrameChunk, IngestReport, object]:
    old = os.environ.get("LASHSCOPE_MF4_NATIVE")
    os.environ["LASHSCOPE_MF4_NATIVE"] = str(native).lower()
    try:
        with open_log(path, strict=strict, chunk_frames=500) as log:
            chunk = FrameChunk.concat(list(log.chunks()))
            return chunk, log.report, log.meta
    finally:
        if old is None:
            del os.environ["LASHSCOPE_MF4_NATIVE"]
        else:
            os.environ["LASHSCOPE_MF4_NATIVE"] = old


def assert_same(a: FrameChunk, b: FrameChunk) -> None:
    assert len(a) == len(b)
    for col in COLUMNS:
        x, y = getattr(a, col), getattr(b, col)
        assert x.shape == y.shape and (x == y).all(), col


def resaved(path: Path, out: Path, compression: int, copies: int = 1) -> Path:
    from asammdf import MDF

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        mdf = MDF.concatenate([str(path)] * copies) if copies > 1 else MDF(str(path))
        mdf.save(str(out), overwrite=True, compression=compression)
    return out


@pytest.mark.parametrize("path", MF4, ids=lambda p: p.name)
def test_canedge_original_equals_asammdf(path: Path) -> None:
    mine, report, meta = read(path)
    ref, _, ref_meta = read(path, native=False)
    assert len(mine) > 1000 and report.ok and report.issues == []
    assert_same(mine, ref)
    assert meta.start_time == ref_meta.start_time and meta.extra == ref_meta.extra  # type: ignore[attr-defined]


@pytest.mark.parametrize("compression", [0, 1, 2], ids=["DT", "DZ-deflate", "DZ-transposed"])
@pytest.mark.parametrize("path", MF4, ids=lambda p: p.name)
def test_asammdf_layouts_equal_asammdf(path: Path, compression: int, tmp_path: Path) -> None:
    f = resaved(path, tmp_path / "x.mf4", compression)
    mine, report, _ = read(f)
    assert report.issues == []
    assert_same(mine, read(f, native=False)[0])
    assert_same(mine, read(path)[0])  # sorted re-save = the unsorted original


def test_data_list_of_blocks_equals_asammdf(tmp_path: Path) -> None:
    f = resaved(MF4[0], tmp_path / "cat.mf4", 2, copies=40)
    mine, report, _ = read(f)
    assert report.issues == [] and len(mine) == 40 * len(read(MF4[0])[0])
    assert_same(mine, read(f, native=False)[0])


def _blocks(data: bytes, kind: bytes) -> list[int]:
    return [m.start() for m in re.finditer(b"##" + kind, data)]


def test_damaged_header_block_is_a_typed_error(tmp_path: Path) -> None:
    data = bytearray(MF4[0].read_bytes())
    data[64:68] = b"##XX"
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match="MF4 structure damaged: expected a ##HD block at offset 64"):
        read(bad)


def test_link_outside_the_file_is_a_typed_error(tmp_path: Path) -> None:
    data = bytearray(MF4[0].read_bytes())
    dg = _blocks(bytes(data), b"DG")[0]
    data[dg + 32:dg + 40] = (len(data) + 4096).to_bytes(8, "little")  # first CG link
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    with pytest.raises(LogFormatError, match="points outside the file"):
        read(bad)


def test_truncated_canedge_file_keeps_every_whole_record(tmp_path: Path) -> None:
    intact = read(MF4[0])[0]
    data = MF4[0].read_bytes()
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(data[:-1001])
    got, report, _ = read(cut)
    assert 0 < len(got) < len(intact)
    assert_same(got, intact.select(np.arange(len(intact)) < len(got)))
    assert [i.kind for i in report.issues] == ["truncated"] and report.issues[0].bytes_lost
    with pytest.raises(TruncatedLogError):
        read(cut, strict=True)


def _damaged_deflate(tmp_path: Path, garbage_tail: bool) -> tuple[Path, FrameChunk]:
    # the 215 kB CANedge file (only under ../shared/data): where its stream is damaged is tuned to its data
    src = shared_file("css-electronics-mf4", "examples", "data-processing", "LOG", "2F6913DB", "00000004",
                      "00000001.MF4")
    f = resaved(src, tmp_path / "z.mf4", 1)
    data = bytearray(f.read_bytes())
    dz = _blocks(bytes(data), b"DZ")[0]
    zlen = int.from_bytes(data[dz + 24 + 16:dz + 24 + 24], "little")
    start, end = dz + 48 + zlen // 2, dz + 48 + zlen
    if garbage_tail:  # the second half of the deflate stream overwritten: zlib finds the stream cut short
        data[start:end] = bytes(end - start)
    else:  # 64 bytes changed in the middle: inflates to the full length, only the checksum fails
        data[start:start + 64] = b"\xff" * 64
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    return bad, read(f)[0]


def test_corrupt_deflate_block_keeps_the_frames_before_the_damage(tmp_path: Path) -> None:
    bad, intact = _damaged_deflate(tmp_path, garbage_tail=True)
    got, report, _ = read(bad)
    assert len(intact) // 3 < len(got) < len(intact)
    assert_same(got, intact.select(np.arange(len(intact)) < len(got)))
    kinds = [i.kind for i in report.issues]
    assert kinds[0] == "corrupt_zlib" and set(kinds[1:]) == {"bad_record"}
    assert sum(i.frames_lost or 0 for i in report.issues) == len(intact) - len(got)  # every lost frame counted
    with pytest.raises(LogFormatError, match="deflate stream damaged"):
        read(bad, strict=True)


def test_deflate_block_failing_only_its_checksum_keeps_nothing_of_it(tmp_path: Path) -> None:
    bad, _ = _damaged_deflate(tmp_path, garbage_tail=False)
    with pytest.raises(LogFormatError, match=r"no frames could be read.*incorrect data check"):
        read(bad)


def test_unknown_record_id_in_unsorted_data_stops_there(tmp_path: Path) -> None:
    intact = read(MF4[0])[0]
    data = bytearray(MF4[0].read_bytes())
    mdf = MdfFile(np.frombuffer(bytes(data), np.uint8))
    dt = mdf.data_groups[0].data_link + 24
    # walk 300 CAN records (id 1) with their payload records (id 2, VLSD) and plant id 99 on the next one
    groups = mdf.data_groups[0].groups
    sizes = {cg.record_id: cg.record_size for cg in groups}
    pos, frames = dt, 0
    while frames < 300 or groups[data[pos] - 1].vlsd:
        rid = data[pos]
        if groups[rid - 1].vlsd:
            pos += 1 + 4 + int.from_bytes(data[pos + 1:pos + 5], "little")
        else:
            frames += rid == 1
            pos += 1 + sizes[rid]
    data[pos] = 99
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    got, report, _ = read(bad)
    assert_same(got, intact.select(np.arange(len(intact)) < 300))
    assert report.issues[0].kind == "bad_record" and "unknown record id 99" in report.issues[0].message


def test_layout_not_read_natively_falls_back_to_asammdf_with_the_reason(tmp_path: Path) -> None:
    data = bytearray(MF4[0].read_bytes())
    mdf = MdfFile(np.frombuffer(bytes(data), np.uint8))
    for cn in _blocks(bytes(data), b"CN"):
        _, links, body = mdf.block(cn, b"CN")
        if mdf.text(links[2]) == "CAN_DataFrame.Dir":
            data[body + 2] = 2  # signed integer: valid MDF, not read natively
    odd = tmp_path / "odd.mf4"
    odd.write_bytes(bytes(data))
    got, report, _ = read(odd)
    assert [i.kind for i in report.issues] == ["mf4_fallback"]
    assert "read through asammdf: channel CAN_DataFrame.Dir" in report.issues[0].message
    assert_same(got, read(odd, native=False)[0])
