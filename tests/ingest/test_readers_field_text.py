"""Text logs as engineers' tools write them: the USB-CAN analyser tab export, serial RXn/TXn dumps and
formats described in a TOML file. Each test writes its files in the tool's layout (no third-party
file is committed); the same frames written as candump -L must read and decode frame for frame alike.
"""

from __future__ import annotations

import gzip
import io
import threading
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from app.cli import main
from app.cli.decode import decode_log
from app.errors import AppError, FormatFileError, LogFormatError, UnsupportedFormatError
from app.ingest.database import load_database
from app.ingest.frames import FrameChunk, FrameFlag
from app.ingest.readers import described, open_log, sniff_format
from app.ingest.readers.described import ENV, parse_layout, register_format_file

DBC = Path(__file__).resolve().parents[2] / "dbc" / "lashscope_ev.dbc"
EXT, TX = int(FrameFlag.EXTENDED), int(FrameFlag.TX)

Frame = tuple[int, int, int, bool, bool, bytes]  # t in 10 ms ticks, channel, id, extended, tx, data


def _frames(n: int = 400, seed: int = 3) -> list[Frame]:
    """Frames of the project's DBC messages (11-bit) and two 29-bit IDs on two channels, 10 ms ticks."""
    rng = np.random.default_rng(seed)
    ids = [(0xA0, False), (0x100, False), (0x101, False), (0x200, False), (0x310, False),
           (0x1BFFDA00, True), (0x18FF50E5, True)]
    out: list[Frame] = []
    tick = 4711
    for i in range(n):
        tick += int(rng.choice([0, 1, 1, 2]))
        ident, ext = ids[int(rng.integers(len(ids)))]
        dlc = 8 if ident < 0x400 else int(rng.integers(0, 9))
        out.append((tick, 0 if i == 0 else int(rng.integers(2)), ident, ext, bool(rng.random() < 0.1),
                    rng.integers(0, 256, dlc, dtype=np.uint8).tobytes()))
    return out


def candump(frames: list[Frame]) -> str:
    """Epoch seconds, IDs of 3 (11-bit) or 8 (29-bit) hex digits, `` T`` for a transmitted frame."""
    return "".join(f"({1_700_000_000 + t // 100}.{t % 100:02d}0000) can{ch} {f'{i:08X}' if ext else f'{i:03X}'}#"
                   f"{d.hex().upper()}{' T' if tx else ''}\n" for t, ch, i, ext, tx, d in frames)


def analyser_tsv(frames: list[Frame]) -> str:
    head = "ParserFlags\tCh\tCounter\tT/R\tTime\tFlags\tCAN ID\tLen\tData\tParser Name\tdefault\n"
    rows = [f"1\t{ch}\t{n + 1}\t{'TX' if tx else 'RX'}\t{t * 10}\t\t0x{i:08x}\t{len(d)}\t"
            f"{('0x' + ' '.join(f'{b:02x}' for b in d) + ' ') if d else ''}\tDefault Parser\t\n"
            for n, (t, ch, i, _, tx, d) in enumerate(frames)]
    return head + "".join(rows)


def serial_dump(frames: list[Frame]) -> str:
    head = "=~=~=~=~=~=~=~=~=~=~=~= PuTTY log 2025.05.22 09:20:45 =~=~=~=~=~=~=~=~=~=~=~=\r\n"
    return head + "".join(f"({t / 100:.2f}) {'TX' if tx else 'RX'}{ch} {i:X} [{len(d)}]"
                          f"{''.join(f' {b:02X}' for b in d)}\r\n" for t, ch, i, _, tx, d in frames)


BENCH_REGEX = (r"^(?P<time>\d+\.\d+);(?P<channel>\d);(?P<dir>[RT]x);(?P<id>[0-9A-F]+);(?P<ext>[SX]);"
               r"(?P<dlc>\d);(?P<data>[0-9A-F]*)$")
REGEX_LAYOUT = f"""
name = "bench logger"
regex = '{BENCH_REGEX}'
time_unit = "ms"
data_encoding = "hex_string"
skip_lines = 2
extended = "field"
extended_values = ["X"]
channel_base = 1
"""


def regex_logger(frames: list[Frame]) -> str:
    head = "bench logger v2 export\ntime_ms;bus;dir;id;fmt;len;data\n"
    return head + "".join(f"{t * 10}.000;{ch + 1};{'Tx' if tx else 'Rx'};{i:X};{'X' if ext else 'S'};{len(d)};"
                          f"{d.hex().upper()}\n" for t, ch, i, ext, tx, d in frames)


COLUMN_LAYOUT = """
separator = "whitespace"
columns = { time = 0, id = 2, dir = 3, channel = 1, data = 4 }
data_to_end = true
time_unit = "us"
extended = "digits"
comment = "#"
"""


def column_logger(frames: list[Frame]) -> str:
    rows = ["# us ch id dir bytes...\n"]
    for t, ch, i, ext, tx, d in frames:
        ident = f"{i:08X}" if ext else f"{i:03X}"
        rows.append(f"{t * 10_000} {ch} {ident} {'tx' if tx else 'rx'} {' '.join(f'{b:02x}' for b in d)}\n")
    return "".join(rows)


def _read(text: str, name: str, **kw: object) -> tuple[FrameChunk, object]:
    stream = io.BytesIO(text.encode("latin-1"))
    stream.name = name  # type: ignore[attr-defined]
    with open_log(stream, **kw) as log:  # type: ignore[arg-type]
        chunk = FrameChunk.concat(list(log.chunks()))
    return chunk, log


def _same_frames(a: FrameChunk, b: FrameChunk) -> None:
    assert len(a) == len(b)
    for col in ("t_ns", "channel", "arb_id", "flags", "dlc"):
        assert getattr(a, col).tolist() == getattr(b, col).tolist(), col
    assert np.array_equal(a.data[:, :8], b.data[:, :8])


@pytest.fixture(scope="module")
def frames() -> list[Frame]:
    return _frames()


@pytest.mark.parametrize(("writer", "name", "fmt"), [(analyser_tsv, "EV-CANeplus2.log", "analyser_tsv"),
                                                     (serial_dump, "drive.log", "serial_dump")])
def test_sniffed_and_read_like_candump(frames: list[Frame], writer: object, name: str, fmt: str) -> None:
    text = writer(frames)  # type: ignore[operator]
    assert sniff_format(text.encode(), name) == fmt
    assert sniff_format(gzip.compress(text.encode()), name + ".gz") == fmt
    ref, ref_log = _read(candump(frames), "copy.log")
    chunk, log = _read(text, name)
    assert log.meta.format == fmt and log.report.issues == []  # type: ignore[attr-defined]
    _same_frames(chunk, ref)
    assert chunk.t_ns[0] == 0 and ref_log.meta.start_clock == "epoch_utc"  # type: ignore[attr-defined]
    assert log.meta.start_clock == "unknown"  # type: ignore[attr-defined]
    assert float(log.meta.extra["clock_at_start_s"]) == pytest.approx(frames[0][0] / 100)  # type: ignore[attr-defined]
    assert (chunk.flags & EXT != 0).sum() == sum(f[3] for f in frames) > 0
    assert (chunk.flags & TX != 0).sum() == sum(f[4] for f in frames) > 0


@pytest.mark.parametrize(("layout", "writer"), [(REGEX_LAYOUT, regex_logger), (COLUMN_LAYOUT, column_logger)])
def test_described_format_reads_like_candump(tmp_path: Path, frames: list[Frame], layout: str, writer: object) -> None:
    desc = tmp_path / "logger.toml"
    desc.write_text(layout)
    ref, _ = _read(candump(frames), "copy.log")
    chunk, log = _read(writer(frames), "bench.txt", layout=desc)  # type: ignore[operator]
    assert log.meta.format == "described" and log.report.issues == []  # type: ignore[attr-defined]
    _same_frames(chunk, ref)


def test_decode_report_equals_the_candump_copy(tmp_path: Path, frames: list[Frame],
                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """Decoding with the project's DBC gives the same per-ID counts, periods and decoded frames."""
    monkeypatch.setattr(described, "_registered", [])
    loaded = load_database(DBC)
    files = {"copy.log": candump(frames), "leaf.log": analyser_tsv(frames), "putty.log": serial_dump(frames),
             "bench.txt": regex_logger(frames)}
    (tmp_path / "bench.toml").write_text(REGEX_LAYOUT)
    reports = {}
    for name, text in files.items():
        (tmp_path / name).write_text(text)
    register_format_file(tmp_path / "bench.toml")  # recognised by content from now on, in this process
    for name in files:
        reports[name] = decode_log(tmp_path / name, loaded)
    ref = reports.pop("copy.log")
    assert ref.frames_decoded > 250
    for name, rep in reports.items():
        assert rep.frames_read == ref.frames_read == len(frames), name
        assert rep.frames_decoded == ref.frames_decoded, name
        assert rep.ids == ref.ids, name  # per channel and ID: count, period, jitter, gaps
    assert reports["bench.txt"].format == "described"


def test_analyser_export_salvage_and_strict() -> None:
    lines = analyser_tsv(_frames(30)).splitlines(keepends=True)
    lines[5] = lines[5].replace("\t0x00000", "\t0xZZ000", 1)          # garbled ID
    lines[9] = "1\t0\t9\tRX\t47\x00\x01\n"                               # binary
    lines[12] = lines[12].replace("\t8\t", "\t9\t", 1)                 # Len beyond 8
    lines.append("1\t0\t31\tRX\t48000\t\t0x00000100\t8\t0x01 02 03")   # cut: fewer bytes than Len
    chunk, log = _read("".join(lines), "cut.log")
    assert len(chunk) == 27
    assert [(i.kind, i.line) for i in log.report.issues] == [  # type: ignore[attr-defined]
        ("non_hex", 6), ("bad_line", 10), ("bad_line", 13), ("short_data", 32)]
    with pytest.raises(LogFormatError, match=r"cut\.log: row skipped: CAN ID .* \(line 6\)"):
        _read("".join(lines), "cut.log", strict=True)


def test_serial_dump_salvage_and_strict() -> None:
    text = serial_dump(_frames(20)).replace("\r\n", "\r\n 00 10 00 00\r\n", 1)  # the capture starts mid-line
    text += "(801.71) RX0 30B"  # ends mid-line
    chunk, log = _read(text, "putty.log")
    assert len(chunk) == 20
    assert [(i.kind, i.line) for i in log.report.issues] == [("bad_line", 2), ("short_data", 23)]  # type: ignore[attr-defined]
    assert log.meta.extra["capture_opened"] == "2025-05-22T09:20:45"  # type: ignore[attr-defined]
    with pytest.raises(LogFormatError, match=r"putty\.log: line skipped: not a .* \(line 2\)"):
        _read(text, "putty.log", strict=True)


def test_described_salvage_and_strict(tmp_path: Path) -> None:
    desc = tmp_path / "bench.toml"
    desc.write_text(REGEX_LAYOUT)
    lines = regex_logger(_frames(20)).splitlines(keepends=True)
    lines[4] = lines[4].replace(";8;", ";9;", 1)  # length says 9 for 8 bytes: not a CAN length
    lines[7] = "garbage\n"
    chunk, log = _read("".join(lines), "bench.txt", layout=desc)
    assert len(chunk) == 18
    assert [(i.kind, i.line) for i in log.report.issues] == [("bad_line", 5), ("bad_line", 8)]  # type: ignore[attr-defined]
    with pytest.raises(LogFormatError, match=r"bench\.txt: line skipped: length 9 .* \(line 5\)"):
        _read("".join(lines), "bench.txt", layout=desc, strict=True)


def test_user_descriptions_join_recognition_by_content(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       frames: list[Frame]) -> None:
    text = column_logger(frames)
    with pytest.raises(UnsupportedFormatError, match=r"supported formats: blf .*analyser_tsv"):
        _read(text, "rig.txt")
    folder = tmp_path / "formats"
    folder.mkdir()
    (folder / "rig.toml").write_text(COLUMN_LAYOUT)
    monkeypatch.setenv(ENV, str(folder))
    chunk, log = _read(text, "rig.txt")
    assert log.meta.format == "described" and log.meta.extra["description"] == "rig"  # type: ignore[attr-defined]
    assert len(chunk) == len(frames)
    ref, _ = _read(candump(frames), "copy.log")  # a candump log is still a candump log
    assert len(ref) == len(frames)


@pytest.mark.parametrize(("text", "message"), [
    ('regex = "("', r"x\.toml: regex: not a valid regular expression"),
    ('regex = "(?P<time>\\\\d+) (?P<id>\\\\w+)"', r"regex: needs the named group\(s\) \(\?P<data>\.\.\.\)"),
    ('columns = { time = 0, id = 1 }', r"columns: needs a position for data"),
    ('columns = { time = 0, id = 1, data = 2, speed = 3 }', r"columns\.speed: unknown field"),
    ('columns = { time = 0, id = "1", data = 2 }', r"columns\.id: expected a column position"),
    ('columns = { time = 0, id = 1, data = 2 }\ntime_unit = "sec"', r"time_unit: 'sec': choose from s, ms, us, ns"),
    ('columns = { time = 0, id = 1, data = 2 }\ndata_encoding = "b64"', r"data_encoding: 'b64': choose from"),
    ('columns = { time = 0, id = 1, data = 2 }\nextended = "field"', r"extended: 'field' needs an ext field"),
    ('columns = { time = 0, id = 1, data = 2 }\nskip_lines = "1"', r"skip_lines: expected int, got '1'"),
    ('columns = { time = 0, id = 1, data = 2 }\nseparator = ";;"', r"separator: one character"),
    ('columns = { time = 0, id = 1, data = 2 }\nbase = 16', r"base: unknown field"),
    ('name = "x"', r"regex: give either regex .* or columns .*, not neither"),
    ("columns = {", r"x\.toml: not valid TOML"),
])
def test_bad_descriptions_name_the_field(text: str, message: str) -> None:
    with pytest.raises(FormatFileError, match=message) as err:
        parse_layout(text, "x.toml")
    assert err.value.code == "format_file"


def test_missing_description_file(tmp_path: Path) -> None:
    with pytest.raises(FormatFileError, match="cannot read the format description"):
        open_log(io.BytesIO(b"1 2 3\n"), layout=tmp_path / "none.toml")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=2000), st.sampled_from([REGEX_LAYOUT, COLUMN_LAYOUT]))
def test_arbitrary_bytes_with_a_description(payload: bytes, layout: str) -> None:
    """Whatever the bytes, a described read ends with frames or a typed error, never a crash or a hang."""
    parsed = parse_layout(layout, "fuzz.toml")

    def work() -> None:
        try:
            with open_log(io.BytesIO(payload), layout=parsed, chunk_frames=7) as log:
                FrameChunk.concat(list(log.chunks()))
        except AppError:
            pass

    worker = threading.Thread(target=work, daemon=True)
    worker.start()
    worker.join(30)
    assert not worker.is_alive()


def test_cli_format_file(tmp_path: Path, frames: list[Frame], capsys: pytest.CaptureFixture[str],
                         monkeypatch: pytest.MonkeyPatch) -> None:
    """``decode --format-file``: the log is read with the description; a wrong one is one line with its code."""
    monkeypatch.setattr(described, "_registered", [])
    monkeypatch.setenv(ENV, "")  # restored afterwards: the command adds the description to it
    (tmp_path / "bench.txt").write_text(regex_logger(frames))
    (tmp_path / "bench.toml").write_text(REGEX_LAYOUT)
    assert main(["decode", str(tmp_path / "bench.txt"), "--dbc", str(DBC), "--format-file",
                 str(tmp_path / "bench.toml")]) == 0
    out = capsys.readouterr().out
    assert f"bench.txt (described), database lashscope_ev.dbc\nframes read {len(frames)}, decoded" in out
    monkeypatch.setattr(described, "_registered", [])
    (tmp_path / "bad.toml").write_text(REGEX_LAYOUT.replace('time_unit = "ms"', 'time_unit = "msec"'))
    assert main(["decode", str(tmp_path / "bench.txt"), "--dbc", str(DBC), "--format-file",
                 str(tmp_path / "bad.toml")]) == 2
    err = capsys.readouterr().err
    assert err == "lashscope: error [format_file]: bad.toml: time_unit: 'msec': choose from s, ms, us, ns\n"


def test_the_documented_examples_read_their_example_lines() -> None:
    import re

    doc = (Path(__file__).resolve().parents[2] / "docs" / "ingest-readers.md").read_text()
    bench, rig = (parse_layout(b, "doc.toml") for b in re.findall(r"```toml\n(.*?)```", doc, re.S))
    assert bench.parse("12.340;1;Rx;1BFFDA00;X;8;E3EA312E80EAF505") == (
        12_340_000, 0, 0x1BFFDA00, EXT, 8, bytes.fromhex("E3EA312E80EAF505"))
    assert rig.parse("1700000000123456 0 18FF50E5 rx 01 02 03") == (
        1_700_000_000_123_456_000, 0, 0x18FF50E5, EXT, 3, b"\x01\x02\x03")
