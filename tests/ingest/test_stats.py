"""Bus statistics: periods and jitter, timestamp anomalies per bus, alive-counter gaps."""

from __future__ import annotations

import cantools
import numpy as np
import pytest

from app.ingest.decode import VectorDecoder
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.stats import DecodeReport, StatsAccumulator, counter_modulus

DBC = '''VERSION ""
NS_ :
BS_:
BU_: A
BO_ 256 Fast: 8 A
 SG_ Value : 0|16@1- (1,0) [0|0] "" A
 SG_ Fast_Alive : 48|4@1+ (1,0) [0|14] "" A
BO_ 512 Slow: 8 A
 SG_ RollingCounter : 0|8@1+ (1,0) [0|255] "" A
 SG_ Temp : 8|8@1+ (1,-40) [0|0] "" A
BA_DEF_ BO_ "GenMsgCycleTime" INT 0 10000;
BA_ "GenMsgCycleTime" BO_ 256 10;
'''


@pytest.fixture(scope="module")
def db() -> cantools.database.can.Database:
    return cantools.database.load_string(DBC, database_format="dbc")


def make_chunk(t_ns: list[int] | np.ndarray, ids: list[int] | np.ndarray, channel: list[int] | np.ndarray,
               data: np.ndarray | None = None, flags: np.ndarray | None = None) -> FrameChunk:
    n = len(t_ns)
    return FrameChunk(np.asarray(t_ns, np.int64), np.asarray(channel, np.int16), np.asarray(ids, np.uint32),
                      np.zeros(n, np.uint8) if flags is None else flags, np.full(n, 8, np.uint8),
                      np.zeros((n, 8), np.uint8) if data is None else data)


def test_periods_and_jitter_across_chunks(db: cantools.database.can.Database) -> None:
    rng = np.random.default_rng(0)
    t = np.cumsum(10_000_000 + rng.integers(-200_000, 200_000, 2000))
    acc = StatsAccumulator(db)
    for part in np.array_split(np.arange(t.size), 7):  # split anywhere: the result must not change
        acc.add_chunk(make_chunk(t[part], [256] * part.size, [0] * part.size))
    acc.add_chunk(make_chunk([5, 6], [0x7FF, 0x7FF], [1, 1]))
    report = acc.fill(DecodeReport())
    fast = next(s for s in report.ids if s.arb_id == 256)
    dt = np.diff(t) / 1e6
    assert fast.count == 2000 and fast.message == "Fast" and fast.cycle_ms == 10.0
    assert fast.period_ms == pytest.approx(dt.mean(), rel=1e-12)
    assert fast.jitter_ms == pytest.approx(dt.std(), rel=1e-6)
    assert (fast.min_gap_ms, fast.max_gap_ms) == (pytest.approx(dt.min()), pytest.approx(dt.max()))
    assert report.frames_read == 2002 and report.frames_unknown_id == 2


def test_timestamp_anomalies_per_bus(db: cantools.database.can.Database) -> None:
    # bus 0 and bus 1 interleave with different clocks: not an anomaly; a real step back on bus 1 is
    t = [0, 500, 10, 510, 20, 505, 3_000_000_020, 530]
    ch = [0, 1, 0, 1, 0, 1, 0, 1]
    acc = StatsAccumulator(db, jump_s=1.0)
    acc.add_chunk(make_chunk(t[:4], [256] * 4, ch[:4]))
    acc.add_chunk(make_chunk(t[4:], [256] * 4, ch[4:]))
    report = acc.fill(DecodeReport())
    assert report.anomaly_counts == {"backwards": 1, "jump": 1}
    kinds = {(a.kind, a.channel, a.frame) for a in report.timestamp_anomalies}
    assert kinds == {("backwards", 1, 5), ("jump", 0, 6)}
    back = next(a for a in report.timestamp_anomalies if a.kind == "backwards")
    assert back.dt_s == pytest.approx(-5e-9)


def test_counter_gaps(db: cantools.database.can.Database) -> None:
    alive = np.r_[np.arange(30) % 15, [3, 4, 4, 5, 9]]  # 0..14 twice (the wrap is no gap), then gaps
    n = alive.size
    data = np.zeros((n, 8), np.uint8)
    data[:, 6] = alive
    chunk = make_chunk(np.arange(n) * 10_000_000, [256] * n, [0] * n, data)
    acc = StatsAccumulator(db)
    dec = VectorDecoder(db)
    half = n // 2
    for part in (chunk.select(np.arange(n) < half), chunk.select(np.arange(n) >= half)):
        acc.add_chunk(part)
        acc.add_decoded(dec.decode(part))
    report = acc.fill(DecodeReport())
    (gaps,) = [g for g in report.counter_gaps if g.signal == "Fast_Alive"]
    # steps: ... 14 -> 3 (missed 0,1,2), 3 -> 4, 4 -> 4 (repeat), 4 -> 5, 5 -> 9 (missed 6,7,8)
    assert (gaps.modulus, gaps.frames, gaps.gaps, gaps.missed, gaps.repeats) == (15, n, 2, 6, 1)
    assert gaps.first_gap_s == pytest.approx(0.30)


@pytest.mark.parametrize(("name", "length", "maximum", "modulus"), [
    ("Fast_Alive", 4, 14, 15), ("RollingCounter", 8, 255, 256), ("DI_torque1Counter", 3, 0, 8),
    ("Temp", 8, 255, None), ("Counter", 1, 1, None), ("Counter", 12, 100, None),
])
def test_counter_modulus(name: str, length: int, maximum: int, modulus: int | None) -> None:
    sig = cantools.database.can.Signal(name, 0, length, maximum=maximum)
    assert counter_modulus(sig) == modulus


def test_error_and_remote_frames_counted(db: cantools.database.can.Database) -> None:
    flags = np.array([FrameFlag.ERROR, FrameFlag.REMOTE, 0], np.uint8)
    acc = StatsAccumulator(db)
    acc.add_chunk(make_chunk([0, 1, 2], [0, 256, 256], [0, 0, 0], flags=flags))
    report = acc.fill(DecodeReport())
    assert (report.error_frames, report.remote_frames, report.frames_read) == (1, 1, 3)


def test_id_type_mismatch_reported(db: cantools.database.can.Database) -> None:
    acc = StatsAccumulator(db)
    acc.add_chunk(make_chunk([0, 1], [256, 256], [0, 0], flags=np.array([FrameFlag.EXTENDED] * 2, np.uint8)))
    assert acc.fill(DecodeReport()).id_type_mismatch == {"Fast": 2}


@pytest.mark.parametrize("size", [40, 700])  # a live batch (grouped in Python) and an array-grouped chunk
def test_one_grouping_for_decoder_and_statistics_changes_no_figure(db: cantools.database.can.Database,
                                                                    size: int) -> None:
    """``StatsAccumulator.add`` groups a chunk's frames once for the decoder and the statistics; the report equals
    the one of the separate calls, with error, remote and extended frames, unknown IDs and a second bus."""
    rng = np.random.default_rng(size)
    n = 3000
    t = np.cumsum(rng.integers(200_000, 2_000_000, n))
    ids = rng.choice([256, 512, 0x7FF, 256], n)
    flags = rng.choice(np.array([0, FrameFlag.ERROR, FrameFlag.REMOTE, FrameFlag.EXTENDED], np.uint8), n,
                       p=[0.94, 0.02, 0.02, 0.02])
    channel = np.where(np.arange(n) > 2000, rng.integers(0, 2, n), 0)  # one bus, then two
    data = rng.integers(0, 256, (n, 8)).astype(np.uint8)
    data[:, 6] = np.arange(n) % 15  # Fast_Alive counting 0..14
    data[:, 0] = np.arange(n) % 256  # Slow's rolling counter
    shared, separate = StatsAccumulator(db), StatsAccumulator(db)
    dec_a, dec_b = VectorDecoder(db), VectorDecoder(db)
    for lo in range(0, n, size):
        chunk = make_chunk(t[lo:lo + size], ids[lo:lo + size], channel[lo:lo + size], data[lo:lo + size],
                           flags[lo:lo + size])
        got = shared.add(chunk, dec_a)
        separate.add_chunk(chunk)
        want = dec_b.decode(chunk)
        separate.add_decoded(want)
        assert got.keys() == want.keys()
        for name, dm in want.items():
            np.testing.assert_array_equal(got[name].t_ns, dm.t_ns)
            for sig, values in dm.signals.items():
                np.testing.assert_array_equal(got[name].signals[sig], values)
    a, b = shared.fill(DecodeReport()), separate.fill(DecodeReport())
    assert a.ids == b.ids and a.counter_gaps == b.counter_gaps and a.timestamp_anomalies == b.timestamp_anomalies
    assert (a.frames_read, a.frames_decoded, a.error_frames, a.remote_frames, a.frames_unknown_id) == \
        (b.frames_read, b.frames_decoded, b.error_frames, b.remote_frames, b.frames_unknown_id)
    assert a.error_frames > 0 and a.remote_frames > 0 and a.frames_unknown_id > 0 and a.id_type_mismatch
    assert {s.channel for s in a.ids} == {0, 1}
