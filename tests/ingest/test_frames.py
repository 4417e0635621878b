from __future__ import annotations

import numpy as np
import pytest

from app.ingest.frames import FrameChunk, IngestReport, ReadIssue, iter_frames_py


def _chunk(n: int, width: int, start: int = 0) -> FrameChunk:
    data = np.arange(n * width, dtype=np.uint8).reshape(n, width)
    return FrameChunk(
        np.arange(start, start + n, dtype=np.int64), np.zeros(n, np.int16),
        np.full(n, 0x123, np.uint32), np.zeros(n, np.uint8), np.full(n, width, np.uint8), data,
    )


def test_concat_widens_payloads() -> None:
    both = FrameChunk.concat([_chunk(2, 8), _chunk(1, 64, start=2)])
    assert len(both) == 3 and both.width == 64
    assert both.data[0, 8:].sum() == 0
    frames = list(iter_frames_py([both]))
    assert frames[2][4] == bytes(range(64))


def test_mismatched_columns_rejected() -> None:
    with pytest.raises(ValueError, match="channel"):
        FrameChunk(np.zeros(2, np.int64), np.zeros(1, np.int16), np.zeros(2, np.uint32),
                   np.zeros(2, np.uint8), np.zeros(2, np.uint8), np.zeros((2, 8), np.uint8))


def test_report_merges_issues_past_limit() -> None:
    rep = IngestReport(max_issues=2)
    for i in range(5):
        rep.add(ReadIssue("bad_line", "x", line=i))
    assert len(rep.issues) == 2 and rep.issues[-1].count == 4
