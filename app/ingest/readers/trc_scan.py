"""Vectorised scanner for the common PEAK TRC line: a classic CAN data frame, in every file version.

Shapes accepted (token positions per version; every other line is handed to the Python
parser in ``trc.py``, which diagnoses damage, so both paths share one set of rules)::

    1.0   17)  17535.4  00000100  8  00 11 22 ...             number) offset id dlc data
    1.1   17)  17535.4  Rx  00000100  8  00 11 ...            ... Rx|Tx id dlc data
    1.2   17)  17535.4  1  Rx  00000100  8  00 11 ...         ... bus Rx|Tx id dlc data
    1.3   17)  17535.4  1  Rx  00000100  -  8  00 11 ...      ... bus Rx|Tx id reserved dlc data
    2.x   the columns of ;$COLUMNS, type DT only, direction Rx|Tx where there is a column for it

Offsets are milliseconds (``digits{1,9}[.digits{1,9}]``), identifiers 1-8 hex digits of at
most 29 bits (more than 4 digits: extended, as the parser reads them), the DLC one digit 0-8
(2.x: ``L`` one or two digits, the length ``min(L, 8)``; ``l`` one digit 0-8), data bytes 1-2
hex digits, bus numbers 1-32767. Remote frames, error and status lines, CAN FD, comments,
control bytes and anything damaged are the parser's.
"""

from __future__ import annotations

import numpy as np

from app.ingest.frames import FrameFlag
from app.ingest.readers.text_scan import BOOL, I64, Tokens, tokenise

_EXT, _TX = int(FrameFlag.EXTENDED), int(FrameFlag.TX)
_MAX_BUS = 32767


class Layout:
    """Token positions of a version's frame line (None: the file has no such column)."""

    def __init__(self, version: str, columns: dict[str, int]) -> None:
        self.numbered = not version.startswith("2")  # 1.x lines start with ``N)``
        self.direction: int | None = None
        self.kind_1x: int | None = None  # 1.x: the Rx/Tx column (1.0 has none)
        self.length_col: str = "dlc"  # 1.x and 2.x "L": a DLC; 2.x "l": a data length
        if version.startswith("2"):
            self.time, self.kind, self.ident, self.data = columns["O"], columns["T"], columns["I"], columns["D"]
            self.bus = columns.get("B")
            self.direction = columns.get("d")
            self.length = columns["l"] if "l" in columns else columns["L"]
            self.length_col = "l" if "l" in columns else "L"
            self.min_tokens = max(len(columns) - 1, self.kind + 1)
            return
        self.time = 1
        positions = {"1.0": (None, None, 2, 3), "1.1": (None, 2, 3, 4), "1.2": (2, 3, 4, 5), "1.3": (2, 3, 4, 6)}
        self.bus, self.kind_1x, self.ident, self.length = positions.get(version, positions["1.0"])
        self.kind = -1
        self.data = self.length + 1
        self.min_tokens = self.data


def scan_block(block: bytes, layout: Layout) -> tuple[Tokens, BOOL, tuple[I64, I64, I64, I64, I64], np.ndarray]:
    """Tokens of ``block``, which lines were parsed here, and their frame columns and data, in line order.

    Columns: ``t_ns`` (the line's offset in ns), ``channel`` (the 1-based bus as written, 1 without a bus
    column), ``arb_id``, ``flags``, ``dlc`` (the data length).
    """
    tk = tokenise(block)
    nlines = tk.ends.size
    fast = np.zeros(nlines, bool)
    empty = np.empty(0, np.int64)
    if not tk.tok_start.size:
        return tk, fast, (empty, empty, empty, empty, empty), np.zeros((0, 8), np.uint8)
    at = tk.at
    cand = np.flatnonzero(tk.clean & (tk.ntok >= layout.min_tokens))
    f = tk.first[cand]
    ok = tk.char(f) != ord(";")
    if layout.numbered:
        ok &= tk.last_char(f) == ord(")")
    flags = np.zeros(cand.size, np.int64)
    if layout.kind >= 0:  # 2.x: the type column
        ok &= tk.equals(at(f + layout.kind), b"DT")
    # the direction: 1.1-1.3's type column, 2.x's own column where there is one
    for col in (layout.kind_1x, layout.direction):
        if col is not None:
            d = at(f + col)
            rx, tx = tk.equals(d, b"Rx"), tk.equals(d, b"Tx")
            ok &= rx | tx
            flags |= np.where(tx, _TX, 0)
    if layout.length_col == "L":
        code, len_ok = tk.decimal(at(f + layout.length), 2)
        length = np.minimum(code, 8)
    else:
        length, len_ok = tk.decimal(at(f + layout.length), 1)
        len_ok &= length <= 8
    ok &= len_ok & (tk.ntok[cand] >= layout.data + length)
    data_tok = at(f + layout.data)
    ok &= ~((tk.ntok[cand] > layout.data) & tk.equals(data_tok, b"RTR"))  # 1.x remote frames: the parser's
    id_tok = at(f + layout.ident)
    ident, id_ok = tk.hex_value(tk.tok_start[id_tok], tk.tok_len[id_tok], 8)
    ok &= id_ok & (ident <= 0x1FFFFFFF)
    flags |= np.where(tk.tok_len[id_tok] > 4, _EXT, 0)
    if layout.bus is not None:
        channel, bus_ok = tk.decimal(at(f + layout.bus), 5)
        ok &= bus_ok & (channel >= 1) & (channel <= _MAX_BUS)
    else:
        channel = np.ones(cand.size, np.int64)
    t_ns, ts_ok = tk.time_ns(at(f + layout.time), 6, dot_required=False)
    data, bytes_ok = tk.data_bytes(f + layout.data, length)
    good = ok & ts_ok & bytes_ok
    fast[cand[good]] = True
    return tk, fast, (t_ns[good], channel[good], ident[good], flags[good], length[good]), data[good]
