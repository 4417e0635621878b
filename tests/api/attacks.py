"""Small inputs that ask for a lot of work: compression bombs, pathological DBCs and drivelines.

Shared by the tests of the limits (tests/api/test_work_limits.py, tests/ingest/test_inflate_cap.py)
and the abuse benchmark (bench/attacks_work.py), so both attack the server with the same bytes.
"""

from __future__ import annotations

import gzip
import io
import tempfile
from pathlib import Path

from tests.conftest import REPO

SINGLE_REDUCTION = REPO / "sim" / "presets" / "single_reduction.toml"
BOMB_LINES = {
    "candump": b"(1609459200.000000) can0 123#0011223344556677\n",
    "asc": b"   0.000000 1  123             Rx   d 8 00 11 22 33 44 55 66 77\n",
    "trc": b"     1)         0.0  Rx         0123  8  00 11 22 33 44 55 66 77 \n",
}
BOMB_HEADS = {"asc": b"date Fri Jan 1 00:00:00.000 am 2021\nbase hex  timestamps absolute\n",
              "mf4": b"MDF     4.10    "}


def gzip_bomb(fmt: str, inflated: int) -> bytes:
    """A gzip member of a few kB per 10 MiB that inflates to about ``inflated`` bytes of a ``fmt`` log
    (``candump``, ``asc``, ``trc``, or ``mf4``: the MDF magic and zeros)."""
    unit = BOMB_LINES.get(fmt, bytes(4096))
    block = unit * (2**20 // len(unit))
    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as f:
        f.write(BOMB_HEADS.get(fmt, b""))
        for _ in range(inflated // len(block) + 1):
            f.write(block)
    return out.getvalue()


def damaged_bomb(inflated: int) -> bytes:
    """A gzipped TRC 1.1 of about ``inflated`` bytes whose every line is damaged (a non-hex data byte)."""
    block = b"     1)         0.0  Rx         0123  8  00 11 22 ZZ 44 55 66 77\n" * 16_000
    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", compresslevel=9) as f:
        f.write(b";$FILEVERSION=1.1\n")
        for _ in range(inflated // len(block) + 1):
            f.write(block)
    return out.getvalue()


def blf_bomb(frames: int) -> bytes:
    """A BLF of ``frames`` identical frames at one timestamp: its zlib containers inflate about 280x."""
    import can

    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "bomb.blf"
        writer = can.BLFWriter(path, compression_level=9)
        msg = can.Message(arbitration_id=0x123, data=bytes(8), timestamp=1.0)
        for _ in range(frames):
            writer.on_message_received(msg)
        writer.stop()
        return path.read_bytes()


def overlapping_dbc(signals: int, filler_messages: int = 0) -> bytes:
    """A DBC whose first message carries ``signals`` signals on the same byte (each load finds one
    overlap, so repairing it means one full parse per signal), then ``filler_messages`` plain ones that
    make every parse slower."""
    lines = ["VERSION \"\"", "", "NS_ :", "", "BS_:", "", "BU_: ECU", "", "BO_ 100 Crowded: 8 ECU"]
    lines += [f" SG_ S{i} : 0|8@1+ (1,0) [0|255] \"\" ECU" for i in range(signals)]
    for m in range(filler_messages):
        lines += ["", f"BO_ {200 + m} Filler{m}: 8 ECU"]
        lines += [f" SG_ F{m}_{k} : {8 * k}|8@1+ (1,0) [0|255] \"\" ECU" for k in range(8)]
    return ("\n".join(lines) + "\n").encode()


def many_stage_driveline(stages: int, stiffness: float = 2.5e4) -> bytes:
    """The single-reduction preset with ``stages`` stages: spline stages (ratio 1, ``stiffness`` N m/rad)
    added after the first."""
    text = SINGLE_REDUCTION.read_text(encoding="utf-8")
    head, first, rest = text.partition("[[stage]]\nkind = \"gear\"")
    spline = ("[[stage]]\nkind = \"spline\"\nname = \"s{i}\"\nstiffness = {k:g}\ndamping = 0.5\ninertia = 0.002\n"
              "lash_rad = {{nominal = 0.01, min = 0.005, max = 0.015}}\n\n")
    extra = "".join(spline.format(i=i, k=stiffness) for i in range(stages - 4))
    return (head + extra + first + rest).encode()


# a format description whose time group backtracks exponentially on a line of digits without the ``x`` after them
BACKTRACKING_REGEX = r"^(?P<time>(\d+)+)x;(?P<id>[0-9A-F]+);(?P<data>[0-9A-F]*)$"


def described_format(regex: str = BACKTRACKING_REGEX, **extra: str) -> bytes:
    """A format description (``format_file`` of ``POST /logs``) with ``regex`` and ``extra`` TOML lines."""
    lines = [f"regex = '{regex}'", *(f"{k} = {v}" for k, v in extra.items())]
    return ("\n".join(lines) + "\n").encode()


def backtracking_log(lines: int = 5, digits: int = 40) -> bytes:
    """A text log whose lines make :data:`BACKTRACKING_REGEX` try about 2**``digits`` ways each, gzipped."""
    return gzip.compress(b"t;id;data\n" + (b"1" * digits + b"\n") * lines)
