"""Real captures nobody on this project wrote: Kona EV SavvyCAN CSV and Vector ASC, CANedge MF4."""

from __future__ import annotations

import re
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pytest

from app.errors import UnsupportedFormatError
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import open_log
from tests.conftest import COMMITTED, sample_files, shared_file

KONA_CSV = sample_files("kona-ev", "*.csv")  # tests/data: the first 3500 rows of one (``.head3500.csv``)
KONA_ASC = sample_files("kona-ev/bms_diagnostics", "*.asc")
MF4 = sample_files("css-electronics-mf4", "**/*.MF4")


@pytest.mark.parametrize("path", KONA_CSV, ids=lambda p: p.name)
def test_kona_gvret_csv(path: Path) -> None:
    rows = [line.split(",") for line in path.read_text().splitlines()[1:] if line.strip()]
    with open_log(path) as log:
        chunk = FrameChunk.concat(log.chunks())
    assert log.meta.format == "gvret_csv"
    assert log.meta.start_time is None and log.meta.start_clock == "unknown"  # device clock, not an epoch
    assert len(chunk) == len(rows) > (3_000 if path.name.endswith(".head3500.csv") else 10_000)
    # timestamps: microseconds of the logger clock, kept in logged order (not monotonic across buses), counted
    # from the log's start (the earliest of the first rows) like a BLF's; the logger clock there is kept
    t_us = np.array([int(r[0]) for r in rows], np.int64)
    t0_us = int(t_us[:999].min())
    assert log.meta.extra["clock_at_start_s"] == f"{t0_us // 10**6}.{t0_us % 10**6:06d}".rstrip("0").rstrip(".")
    assert (chunk.t_ns == (t_us - t0_us) * 1000).all()
    assert int(chunk.t_ns.min()) == 0 and int(chunk.t_ns.max()) < 60 * 10**9  # seconds of log, charted from 0
    backwards = int((np.diff(t_us) < 0).sum())
    issues = {i.kind: i for i in log.report.issues}
    assert set(issues) == {"time_backwards"} and issues["time_backwards"].count == backwards > 100
    assert set(np.unique(chunk.channel)) == {0, 1}
    assert (chunk.flags == 0).all() and int(chunk.arb_id.max()) <= 0x7FF
    assert (chunk.dlc == np.array([int(r[4]) for r in rows])).all()
    first = rows[0]
    assert bytes(chunk.data[0, : int(first[4])]) == bytes(int(b, 16) for b in first[5:5 + int(first[4])])


@pytest.mark.parametrize("path", KONA_ASC, ids=lambda p: p.name[:40])
def test_kona_vector_asc(path: Path) -> None:
    text = path.read_text()
    expected = len(re.findall(r"^\s*\d+\.\d+\s+\d+\s+[0-9A-F]+\s+(?:Rx|Tx)\s+d\s", text, re.M))
    header = text.splitlines()[0]
    with open_log(path) as log:
        chunk = FrameChunk.concat(log.chunks())
    assert log.report.ok, log.report.issues
    assert len(chunk) == expected > 500
    # "date Thu, 09 Nov 2023 20:29:27 GMT": an RFC 1123 date in UTC, not Vector's local-time form
    assert log.meta.start_clock == "asc_date_header_utc"
    assert log.meta.start_time == datetime.strptime(header[5:], "%a, %d %b %Y %H:%M:%S GMT").replace(tzinfo=UTC)
    assert set(np.unique(chunk.channel)) == {-1}  # the exporter numbers the channel 0; Vector's are 1-based
    assert (np.diff(chunk.t_ns) >= 0).all()
    assert not (chunk.flags & (FrameFlag.EXTENDED | FrameFlag.FD)).any()


def test_kona_asc_file_names_with_spaces_and_parentheses() -> None:
    path = shared_file("kona-ev", "bms_diagnostics", "Main Relay (+) On.asc")
    with open_log(str(path)) as log:
        n = sum(len(c) for c in log.chunks())
    assert n == 738


@pytest.mark.parametrize("path", MF4, ids=lambda p: p.name)
def test_canedge_mf4_bounded_chunks(path: Path) -> None:
    with open_log(path, chunk_frames=500) as log:
        parts = list(log.chunks())
    assert all(len(p) <= 500 for p in parts) and len(parts) >= 3
    chunk = FrameChunk.concat(parts)
    assert log.meta.start_clock == "mf4_header_utc" and log.meta.start_time is not None
    assert log.meta.start_time.tzinfo is not None and log.meta.start_time.utcoffset().total_seconds() == 0  # type: ignore[union-attr]
    assert (np.diff(chunk.t_ns) >= 0).all() and chunk.t_ns[0] >= 0
    assert set(np.unique(chunk.channel)) <= {0, 1}


def test_canedge_compressed_mfc_is_refused_clearly() -> None:
    # the first 4 KiB of 00000005-643E503A.MFC (527 kB): its container header is what the sniffer reads
    path = COMMITTED.joinpath("css-electronics-mf4", "examples", "other", "concatenate-mf4-by-period", "LOG",
                              "5BC57FEC", "00000001", "00000005-643E503A.head4096.MFC")
    with pytest.raises(UnsupportedFormatError, match="CANedge compressed or encrypted MF4"):
        open_log(path)
