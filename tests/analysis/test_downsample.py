"""Downsampling methods: min/max keeps every extreme; LTTB keeps shape with one row per bucket."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from app.analysis.downsample import BlockExtremes, downsample, lttb_rows, minmax_rows
from app.errors import InputError


def test_minmax_rows_equal_a_plain_bucket_scan() -> None:
    rng = np.random.default_rng(4)
    n, max_points = 10_007, 300
    a, b = rng.normal(size=n).cumsum(), rng.normal(size=n)
    b[rng.random(n) < 0.05] = np.nan
    rows = minmax_rows([a, b], max_points)
    buckets = (max_points - 2) // 4
    size = int(np.ceil(n / buckets))
    expect = {0, n - 1}
    for s in range(0, n, size):
        for y in (a, b):
            seg = y[s:s + size]
            expect |= {s + int(np.nanargmax(seg)), s + int(np.nanargmin(seg))}
    assert rows.tolist() == sorted(expect) and rows.size <= max_points


def test_lttb_keeps_spikes_first_last_and_count() -> None:
    t = np.linspace(0.0, 100.0, 20_001)
    y = np.sin(t)
    spikes = [3_000, 11_111, 17_500]
    y[spikes] += 50.0
    rows = lttb_rows(t, [y], 400)
    assert rows.size == 400 and rows[0] == 0 and rows[-1] == t.size - 1
    assert np.all(np.diff(rows) > 0)
    assert set(spikes) <= set(rows.tolist())


def test_lttb_with_several_columns_and_nan() -> None:
    t = np.arange(5_000.0)
    a = np.sin(t / 50.0)
    b = 1000.0 * np.cos(t / 70.0)  # a different scale: areas are normalised per column
    b[::97] = np.nan
    b[2_345] = 5000.0
    td, cols = downsample(t, {"a": a, "b": b}, 250, "lttb")
    assert td.size == 250 and 5000.0 in cols["b"]
    assert np.array_equal(cols["a"], a[np.searchsorted(t, td)])


def test_short_series_come_back_whole_and_bad_arguments_are_typed() -> None:
    t = np.arange(10.0)
    for method in ("minmax", "lttb"):
        td, cols = downsample(t, {"a": t * 2}, 100, method)  # type: ignore[arg-type]
        assert np.array_equal(td, t) and np.array_equal(cols["a"], t * 2)
    with pytest.raises(InputError, match="method"):
        downsample(t, {"a": t}, 100, "every-third")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="max_points"):
        downsample(t, {"a": t}, 2, "lttb")


@example(2_000, 1_000, 1_000, 14, 0)  # the window empty
@example(2_000, 1_000, 999, 14, 0)  # one row, inside the NaN block
@settings(max_examples=40, deadline=None)
@given(st.integers(2_000, 60_000), st.integers(0, 1_000), st.integers(0, 1_000), st.integers(14, 3_000),
       st.integers(0, 2**16))
def test_block_extremes_keep_every_windows_extremes(n: int, cut_lo: int, cut_hi: int, max_points: int,
                                                     seed: int) -> None:
    rng = np.random.default_rng(seed)
    a = rng.normal(size=n).cumsum()
    b = rng.normal(size=n)
    b[rng.random(n) < 0.05] = np.nan
    b[1_000:1_300] = np.nan  # whole NaN blocks
    ext = BlockExtremes([a, b], block=64)
    lo, hi = cut_lo, n - cut_hi
    rows = ext.rows([a, b], lo, hi, max_points)
    if hi <= lo:  # the cuts meet (n=2000, 1000 cut from each end): an empty window has no rows
        assert rows.size == 0
        return
    assert rows.size <= max_points
    assert rows[0] == lo and rows[-1] == hi - 1 and np.all(np.diff(rows) > 0)
    assert a[rows].max() == a[lo:hi].max() and a[rows].min() == a[lo:hi].min()
    # (fmax/fmin skip NaN; a window inside the NaN block has none to keep, and gives NaN both ways)
    assert np.array_equal([np.fmax.reduce(b[rows]), np.fmin.reduce(b[rows])],
                          [np.fmax.reduce(b[lo:hi]), np.fmin.reduce(b[lo:hi])], equal_nan=True)
