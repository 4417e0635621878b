"""Spacing statistics of time stamps and the burst rule, with values; the decode report's per-ID figures."""

from __future__ import annotations

import numpy as np
import pytest

from app.ingest.frames import FrameChunk
from app.ingest.stats import DecodeReport, GapHistogram, StatsAccumulator, gap_bins
from app.signals.sampling import burst_reason, spacing


def _bursts(n_bursts: int, inner_ms: float = 1.0, cycle_ms: float = 63.0, per_burst: int = 3) -> np.ndarray:
    """A ~48 Hz stream delivered in bursts: ``per_burst`` samples ``inner_ms`` apart every ``cycle_ms``."""
    starts = np.arange(n_bursts) * cycle_ms
    return (starts[:, None] + np.arange(per_burst)[None, :] * inner_ms).ravel() / 1000.0


def test_periodic_stream() -> None:
    sp = spacing(np.arange(101) * 0.01)
    assert sp.samples == 101 and not sp.bursty and sp.reason == ""
    assert sp.mean_ms == pytest.approx(10.0) and sp.median_ms == pytest.approx(10.0)
    assert sp.p95_ms == pytest.approx(10.0) and sp.max_ms == pytest.approx(10.0)
    assert sp.period_s == pytest.approx(0.01) and sp.rate_hz == pytest.approx(100.0)


def test_bursty_stream_mean_is_the_period() -> None:
    sp = spacing(_bursts(100))  # gaps: 1, 1, 61, 1, 1, 61, ...
    assert sp.samples == 300
    assert sp.mean_ms == pytest.approx((63.0 * 99 + 2.0) / 299)  # span / intervals: 20.87 ms
    assert sp.mean_ms == pytest.approx(20.866, abs=1e-3)
    assert sp.median_ms == pytest.approx(1.0) and sp.max_ms == pytest.approx(61.0)
    assert sp.p95_ms == pytest.approx(61.0)
    assert sp.bursty and "median spacing 1 ms is 0.05 of the mean 20.9 ms" in sp.reason
    assert sp.period_s == pytest.approx(0.020866, abs=1e-6)


def test_gapped_stream_and_short_ones() -> None:
    t = np.r_[np.arange(50) * 0.01, 0.49 + 0.2 + np.arange(50) * 0.01]  # a 200 ms hole in a 10 ms stream
    sp = spacing(t)
    assert sp.median_ms == pytest.approx(10.0) and sp.max_ms == pytest.approx(200.0)
    assert sp.mean_ms == pytest.approx(1180.0 / 99)
    assert sp.bursty and sp.reason.startswith("gaps up to 200 ms, 17 times the mean")
    assert spacing([0.0]).mean_ms is None and spacing([]).samples == 0
    assert not spacing(_bursts(3)).bursty  # 8 intervals: too few to judge
    assert burst_reason(100, 10.0, 6.0, 40.0) == ""  # median above half the mean, max under 5 means


def test_histogram_quantiles() -> None:
    rng = np.random.default_rng(3)
    dt = rng.choice([1e6, 5e6, 59e6], size=10_001, p=[0.2, 0.5, 0.3])  # logger ms stamps, as ns
    h = GapHistogram()
    for part in np.array_split(dt, 7):
        h.add(part)
    assert h.quantile(0.5) == np.median(dt) == 5e6  # equal gaps in the bin: exact
    assert h.quantile(0.95) == np.percentile(dt, 95) == 59e6
    jitter = rng.normal(10e6, 0.3e6, 5000)
    h2 = GapHistogram()
    h2.add(jitter)
    assert h2.quantile(0.5) == pytest.approx(np.median(jitter), rel=5e-4)
    assert h2.quantile(0.95) == pytest.approx(np.percentile(jitter, 95), rel=5e-4)
    h3 = GapHistogram()
    h3.add(np.zeros(3))
    assert h3.quantile(0.5) == 0.0 and GapHistogram().quantile(0.5) is None
    h4 = GapHistogram()  # a stamp going backwards: zero and negative gaps share the lowest bin
    h4.add(np.array([10e6, -5.0, 10e6, 0.0, 10e6]))
    assert h4.quantile(0.0) == -2.5 and h4.quantile(1.0) == 10e6


@pytest.mark.parametrize("seed", range(6))
def test_histogram_matches_its_bins_exactly(seed: int) -> None:
    """A quantile is the mean of the gaps in the bin of the exact order statistic, pauses and resets included."""
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(rng.integers(1, 6)):  # chunks of a periodic message with jitter, lost frames and pauses
        n = int(rng.integers(1, 3000))
        dt = np.round(rng.normal(10e6, 0.2e6, n) * rng.choice([1, 2, 3], n, p=[0.9, 0.08, 0.02]))
        dt[rng.random(n) < 0.002] = rng.uniform(1e9, 6e10)  # pauses far above the band
        dt[rng.random(n) < 0.001] = rng.choice([0.0, -3e6])
        parts.append(dt)
    h = GapHistogram()
    for dt in parts:
        h.add(dt)
    every = np.concatenate(parts)
    bins = gap_bins(every)
    for q in (0.0, 0.5, 0.95, 0.999, 1.0):
        ranked = np.sort(every)[round(q * (every.size - 1))]
        assert h.quantile(q) == pytest.approx(every[bins == gap_bins(np.array([ranked]))[0]].mean(), rel=1e-12)
    assert np.all(np.diff(gap_bins(np.sort(every[every > 0]))) >= 0)  # the bins grow with the gap


def test_per_id_report_across_chunks() -> None:
    t_ms = np.round(_bursts(200) * 1000).astype(np.int64)  # 600 frames of one ID, split over chunks
    n = t_ms.size
    chunk = FrameChunk(t_ms * 1_000_000, np.zeros(n, np.int16), np.full(n, 0x123, np.uint32), np.zeros(n, np.uint8),
                       np.full(n, 8, np.uint8), np.zeros((n, 8), np.uint8))
    acc = StatsAccumulator()
    for lo in range(0, n, 128):
        acc.add_chunk(chunk.select((np.arange(n) >= lo) & (np.arange(n) < lo + 128)))
    report = acc.fill(DecodeReport())
    (s,) = report.ids
    assert s.count == 600 and s.median_gap_ms == 1.0 and s.p95_gap_ms == 61.0 and s.max_gap_ms == 61.0
    assert s.period_ms == pytest.approx(63.0 * 199 / 599 + 2 / 599)
    assert s.bursty and "samples come in bursts" in s.bursty_reason


@pytest.mark.parametrize("seed", range(40))
def test_median_p95_is_numpys_percentile_bit_for_bit(seed: int) -> None:
    from app.signals.sampling import median_p95

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 3000)) if seed % 4 else int(rng.integers(1, 25))
    x = rng.normal(10.0, 3.0, n) if seed % 3 else rng.integers(0, 5, n).astype(np.float64)  # ties too
    if seed % 5 == 0:
        x = np.round(x, 1) * 1e-3
    expected = np.percentile(x, [50.0, 95.0])
    assert median_p95(x) == (float(expected[0]), float(expected[1]))
    assert median_p95(np.r_[x, np.nan]) == pytest.approx(tuple(np.percentile(np.r_[x, np.nan], [50.0, 95.0])),
                                                           nan_ok=True)
