"""Alive counters: patterns learned from the data (step, modulus, sequence, constant); gaps where they deviate."""

from __future__ import annotations

from pathlib import Path

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


def faults(kind: str, rng: np.random.Generator) -> tuple[np.ndarray, int, int]:
    """A counter with one kind of injected fault: (values, bits, DBC modulus hint)."""
    if kind == "dropped":  # single frames and short runs lost, 0..14 counter
        v, _ = drop(counting(WINDOW * 12, 1, 15), rng, clusters=20, max_len=3)
        return v, 4, 15
    if kind == "dropped_255":  # an 8-bit counter that loses frames, some of them the value 255
        v = counting(WINDOW * 12, 1, 256, start=7)
        lost = np.r_[np.flatnonzero(v == 255)[[1, 4]], rng.choice(np.arange(300, v.size - 300), 15, replace=False)]
        return np.delete(v, lost), 8, 256
    if kind == "repeats":  # a late task sends its value twice, a down counter
        v = counting(WINDOW * 10, 15, 16)
        at = rng.choice(np.arange(1, v.size), 12, replace=False)
        v[at] = v[at - 1]
        return v, 4, 16
    if kind == "wrap":  # frames lost exactly where the counter wraps
        v = counting(WINDOW * 10, 1, 16)
        wraps = np.flatnonzero(v == 15)[::7]
        return np.delete(v, np.r_[wraps, wraps + 1]), 4, 16
    if kind == "reset":  # the ECU restarts: its counter begins at 0 again, twice
        v = np.r_[counting(1000, 1, 15, start=4), counting(1700, 1, 15), counting(900, 1, 15)]
        return v, 4, 15
    if kind == "stuck":  # the counter stops for a while, then counts on
        v = counting(WINDOW * 9, 1, 16)
        return np.r_[v[:1000], np.full(600, v[999]), v[1000:]], 4, 16
    raise AssertionError(kind)


@pytest.mark.parametrize("kind", ["dropped", "dropped_255", "repeats", "wrap", "reset", "stuck"])
@pytest.mark.parametrize("seed", range(3))
def test_bulk_equals_window_by_window_on_injected_faults(kind: str, seed: int, monkeypatch: pytest.MonkeyPatch) -> None:
    """The bulk-verified summary is the window-by-window learning's, whatever fault the counter shows."""
    rng = np.random.default_rng(seed)
    values, bits, hint = faults(kind, rng)
    splits = int(rng.integers(1, 9))
    flushes = []
    flush = CounterTrack._flush
    monkeypatch.setattr(CounterTrack, "_flush", lambda self, *a, **k: (flushes.append(1), flush(self, *a, **k))[1])
    bulk = run_track(values, bits, hint, splits=splits)
    bulk_flushes = len(flushes)
    monkeypatch.setattr(CounterTrack, "_verify_in_bulk", lambda self: False)
    windows = run_track(values, bits, hint, splits=splits)
    assert bulk == windows
    assert bulk_flushes < len(flushes) - bulk_flushes  # the bulk path judged windows of its own
    expected = {"dropped": ("step +1 mod 15", 20, 0), "repeats": ("step -1 mod 16", bulk.repeats, bulk.repeats),
                "wrap": ("step +1 mod 16", 23, 0), "reset": ("step +1 mod 15", 2, 0),
                "stuck": ("step +1 mod 16", 0, 24),
                "dropped_255": ("step +1 mod 256", bulk.gaps, 0)}[kind]
    assert (bulk.pattern, bulk.gaps, bulk.repeats) == expected
    if kind == "wrap":  # both values around the wrap lost each time
        assert bulk.missed == 2 * 23
    elif kind == "repeats":  # a repeated value stands where the next one should be: a repeat, then a gap of one
        assert bulk.repeats >= 11 and bulk.missed == bulk.repeats
    elif kind == "stuck":  # the stretch is learned as a constant pattern of its own
        assert bulk.pattern_changes == 2
    elif kind == "dropped_255":
        assert bulk.gaps >= 14


MUX_DBC = """VERSION ""
NS_ :
BS_:
BU_: ECU
BO_ 2566831883 CHS_Mux: 8 ECU
 SG_ MuxIndex M : 1|2@0+ (1,0) [0|3] "" ECU
 SG_ MuxAlive : 7|4@0+ (1,0) [0|15] "" ECU
 SG_ WheelFL m0 : 15|16@0+ (0.1,0) [0|6553.4] "rpm" ECU
 SG_ PageCounter m1 : 15|4@0+ (1,0) [0|14] "" ECU
 SG_ VehSpeed m1 : 31|16@0+ (0.01,0) [0|655.34] "km/h" ECU
BO_ 2364539905 INV_Fast: 8 ECU
 SG_ RotorSpeed : 7|16@0- (0.25,0) [-8192|8191.75] "rpm" ECU
 SG_ FastCounter : 39|8@0+ (1,0) [0|255] "" ECU
VAL_ 2566831883 PageCounter 15 "SNA" ;
VAL_ 2364539905 RotorSpeed -32768 "SNA" ;
"""


def test_bulk_equals_window_by_window_on_a_logged_bus(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A BLF with Motorola 29-bit messages: a counter across the pages of a multiplexed message, one in a
    page (with SNA values), an 8-bit one; frames lost, repeated and a reset. The bus report's counter
    findings are the same with and without the bulk verification."""
    import can
    import cantools

    from app.cli.decode import decode_log
    from app.ingest.database import load_database

    dbc = tmp_path / "mux.dbc"
    dbc.write_text(MUX_DBC)
    db = cantools.database.load_file(str(dbc))
    mux, fast = db.get_message_by_name("CHS_Mux"), db.get_message_by_name("INV_Fast")
    rng = np.random.default_rng(5)
    frames = []
    for i in range(4500):  # 2 ms, pages 0 and 1 alternate; the page-1 counter counts page-1 frames
        page = i % 2
        values = {"MuxIndex": page, "MuxAlive": i % 16, "WheelFL": 100.0, "PageCounter": (i // 2) % 15,
                  "VehSpeed": 50.0}
        if page == 1 and 3000 <= i < 3040:
            values["PageCounter"] = 15  # not available for a while: those frames carry no counter value
        frames.append((i * 0.002, mux, values))
    reset = 2600
    for i in range(9000):  # 1 ms; the ECU restarts at frame 2600
        frames.append((i * 0.001 + 0.0003, fast, {"RotorSpeed": 1000.0,
                                                  "FastCounter": (i if i < reset else i - reset) % 256}))
    frames.sort(key=lambda f: f[0])
    lost = set(rng.choice(len(frames), 40, replace=False).tolist())
    with_page_counter = 0  # frames written that carry a page-1 counter value
    with can.BLFWriter(str(tmp_path / "bus.blf")) as w:
        for j, (t, msg, values) in enumerate(frames):
            if j in lost:
                continue
            data = msg.encode(values, strict=False)
            for _ in range(2 if j % 997 == 0 else 1):  # now and then a frame is sent twice
                with_page_counter += msg is mux and values["MuxIndex"] == 1 and values["PageCounter"] != 15
                w.on_message_received(can.Message(timestamp=1.7e9 + t, arbitration_id=msg.frame_id,
                                                  is_extended_id=True, data=data, channel=0))
    loaded = load_database(dbc)
    bulk = decode_log(tmp_path / "bus.blf", loaded).counter_gaps
    monkeypatch.setattr(CounterTrack, "_verify_in_bulk", lambda self: False)
    windows = decode_log(tmp_path / "bus.blf", loaded).counter_gaps
    assert bulk == windows
    got = {g.signal: g for g in bulk}
    assert set(got) == {"MuxAlive", "PageCounter", "FastCounter"}
    assert got["MuxAlive"].pattern == "step +1 mod 16" and got["MuxAlive"].gaps > 0
    assert got["PageCounter"].pattern == "step +1 mod 15" and got["PageCounter"].frames == with_page_counter
    assert got["FastCounter"].pattern == "step +1 mod 256" and got["FastCounter"].gaps >= 1
