"""Alive counters: patterns learned from the data (step, modulus, sequence, constant); gaps where they deviate."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from app.ingest.counters import RUN, WINDOW, CounterGaps, CounterTrack
from tests.conftest import shared_file


def run_track(values: np.ndarray, bits: int, hint: int | None = None, splits: int = 1,
              period_ns: int = 10_000_000) -> CounterGaps:
    """Feed ``values`` (in ``splits`` parts) to a tracker and summarise."""
    track = CounterTrack("M", "Counter", 0, bits, 2**bits if hint is None else hint)
    t = np.arange(values.size, dtype=np.int64) * period_ns
    for part in np.array_split(np.arange(values.size), splits):
        track.feed(values[part].astype(np.float64), t[part])
    return track.finish()


def counting(n: int, step: int, modulus: int, start: int = 0) -> np.ndarray:
    return (start + step * np.arange(n)) % modulus


def drop(values: np.ndarray, rng: np.random.Generator, clusters: int, max_len: int) -> tuple[np.ndarray, int]:
    """Remove ``clusters`` separated runs of 1..max_len frames; the values kept and the frames removed."""
    keep = np.ones(values.size, bool)
    starts = np.sort(rng.choice(np.arange(20, values.size - 20, 3 * max_len), clusters, replace=False))
    lost = 0
    for s in starts:
        k = int(rng.integers(1, max_len + 1))
        keep[s:s + k] = False
        lost += k
    return values[keep], lost


@pytest.mark.parametrize(("bits", "step", "modulus", "text"), [
    (4, 1, 16, "step +1 mod 16"), (4, 1, 15, "step +1 mod 15"), (2, 1, 4, "step +1 mod 4"),
    (4, 2, 16, "step +2 mod 16"), (4, 4, 16, "step +4 mod 16"), (8, 16, 256, "step +16 mod 256"),
    (8, 1, 256, "step +1 mod 256"), (4, 15, 16, "step -1 mod 16"), (8, 241, 256, "step -15 mod 256"),
    (3, 1, 8, "step +1 mod 8"),
])
def test_clean_counters_have_no_gaps(bits: int, step: int, modulus: int, text: str) -> None:
    # the DBC range says nothing useful here (2**bits): the modulus comes from the wrap-arounds
    g = run_track(counting(3000, step, modulus, start=3 % modulus), bits, splits=7)
    assert (g.kind, g.pattern, g.gaps, g.missed, g.repeats, g.fit) == ("step", text, 0, 0, 0, 1.0)
    assert g.modulus == modulus and g.frames == 3000 and g.pattern_changes == 0


@pytest.mark.parametrize(("bits", "step", "modulus"), [(4, 1, 16), (4, 1, 15), (4, 2, 16), (4, 4, 16),
                                                       (8, 16, 256), (8, 1, 256), (4, 15, 16)])
def test_dropped_frames_counted(bits: int, step: int, modulus: int) -> None:
    rng = np.random.default_rng(bits * 1000 + step * 10 + modulus)
    period = modulus // np.gcd(step, modulus)
    # at most period - 2 lost in a row: a whole cycle lost looks like a repeat
    values, lost = drop(counting(4000, step, modulus), rng, clusters=12, max_len=min(3, period - 2))
    g = run_track(values, bits, splits=5)
    assert (g.gaps, g.missed, g.repeats) == (12, lost, 0)
    assert g.first_gap_s is not None and g.fit == pytest.approx(1 - 12 / (values.size - 1))


def test_gap_across_the_wrap_and_repeats() -> None:
    # 0..14 counter (modulus 15 from the data even though the DBC allows 0..15)
    v = counting(600, 1, 15)
    v = np.r_[v[:100], v[103:300], v[299], v[300:]]  # 3 lost where 14 -> 0 wraps (frames 100..102), one repeat
    assert v[99] == 9 and v[100] == 13
    wrap = np.r_[counting(45, 1, 15), counting(60, 1, 15, start=2)]  # ..., 14 -> 2: 0 and 1 lost at the wrap
    g = run_track(np.r_[v, wrap], 4)
    assert g.pattern == "step +1 mod 15"
    # v's last value is 14 (600 = 40 * 15 frames) and wrap starts at 0: no gap there
    assert (g.gaps, g.missed, g.repeats) == (2, 3 + 2, 1)


def test_constant_counter_is_not_stuck() -> None:
    g = run_track(np.full(500, 7), 8)
    assert (g.kind, g.pattern, g.gaps, g.missed, g.repeats) == ("constant", "constant 7", 0, 0, 0)


def test_counter_that_stops_counting_shows_repeats() -> None:
    v = np.r_[counting(1000, 1, 16), np.full(5, 7)]  # the ECU stopped counting at 7 (1000 % 16 == 8 -> last is 7)
    g = run_track(v, 4)
    assert g.pattern == "step +1 mod 16" and (g.gaps, g.repeats) == (0, 5)


def test_two_nibble_sequence() -> None:
    # like the Kona SBW_354 counter: high nibble counts down, low nibble up -> 16 values in a fixed order
    hi = (7 - np.arange(16)) % 16
    lo = (11 + np.arange(16)) % 16
    cycle = hi * 16 + lo
    v = np.tile(cycle, 100)
    g = run_track(v, 8)
    assert (g.kind, g.modulus, g.gaps, g.missed) == ("sequence", 16, 0, 0)
    g = run_track(np.delete(v, [500, 501, 900]), 8)  # frames lost: counted along the learned order
    assert (g.gaps, g.missed) == (2, 3)


def test_direction_change_is_a_pattern_change_not_gaps() -> None:
    v = np.r_[counting(700, 3, 4, start=2), counting(1400, 1, 4, start=0), counting(500, 3, 4, start=3)]
    g = run_track(v, 2, splits=9)
    assert g.pattern == "step +1 mod 4" and g.pattern_changes == 2
    assert g.gaps == 0 and g.unchecked <= 2 * RUN  # at most the steps around the two switches are not judged


def test_irregular_values_are_not_checked() -> None:
    rng = np.random.default_rng(3)
    g = run_track(rng.integers(0, 4, 1000), 2)
    assert (g.kind, g.gaps, g.missed) == ("irregular", 0, 0) and g.unchecked == 999


@settings(max_examples=25, deadline=None)
@given(st.integers(1, 12), st.sampled_from([(4, 1, 16), (4, 1, 15), (4, 2, 16), (8, 16, 256), (8, 255, 256)]),
       st.integers(0, 10**6))
def test_chunking_does_not_change_the_result(splits: int, pattern: tuple[int, int, int], seed: int) -> None:
    bits, step, modulus = pattern
    rng = np.random.default_rng(seed)
    values, lost = drop(counting(WINDOW * 3 + 17, step, modulus), rng, clusters=4, max_len=1)
    one, many = run_track(values, bits), run_track(values, bits, splits=splits)
    assert one == many and (one.gaps, one.missed) == (4, lost)


def test_kona_capture_counters() -> None:
    from app.cli.decode import decode_log
    from app.ingest.database import load_database

    log = shared_file("kona-ev", "230112-7-2019-pcan-ccan-power-off-on-ready-off.csv")
    dbc = shared_file("kona-ev", "dbc", "pcan.dbc")
    report = decode_log(log, load_database(dbc))
    got = {(g.message, g.signal, g.channel): g for g in report.counter_gaps}
    sbw = got[("SBW_354", "Counter", 0)]  # steps by -15 mod 256 except where the low nibble wraps
    assert (sbw.kind, sbw.modulus, sbw.gaps, sbw.missed) == ("sequence", 16, 0, 0)
    for key in [("CGW_462", "SometimesCounter", 0), ("VCU_5D9", "Counter_Charging", 0)]:
        assert got[key].kind == "constant" and got[key].gaps == 0
    tcf = got[("TractionControlFast", "Counter1", 0)]  # 0..14 ("skips 0xF")
    assert (tcf.pattern, tcf.gaps) == ("step +1 mod 15", 0)
    # the VCU counters all lost the same frame at the same moment
    for name, sig in [("VCU_109", "Counter"), ("VCU_200", "Counter"), ("VCU_201", "Counter1")]:
        g = got[(name, sig, 0)]
        assert (g.pattern, g.gaps, g.missed) == ("step +1 mod 4", 1, 1)
        assert g.first_gap_s == pytest.approx(2.096, abs=2e-3)  # since the log's start (1955.709 s logger clock)
    # VCU_202 counts down, up, down: a pattern change each time, not hundreds of gaps
    vcu202 = got[("VCU_202", "Counter", 0)]
    assert vcu202.pattern_changes >= 2 and vcu202.gaps <= 3
    assert got[("UNK_471", "MaybeCounter", 0)].kind == "irregular"


@pytest.mark.parametrize("seed", range(6))
def test_bulk_verification_equals_window_by_window(seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """Perfect stretches are counted in bulk; the summary is the one window-by-window learning gives."""
    rng = np.random.default_rng(seed)
    clean = np.r_[counting(WINDOW * 9 + 5, 1, 15), counting(WINDOW * 4, 15, 16, start=3), counting(700, 2, 16)]
    values, _ = drop(clean, rng, clusters=6, max_len=3)
    values[rng.integers(0, values.size, 3)] = 7  # values off the pattern and repeats
    splits = int(rng.integers(1, 8))
    bulk = run_track(values, 4, splits=splits)
    monkeypatch.setattr(CounterTrack, "_verify_in_bulk", lambda self: False)
    windows = run_track(values, 4, splits=splits)
    assert bulk == windows
    assert bulk.gaps >= 6 and bulk.pattern_changes >= 2
