"""Vectorised scanner for the common Vector ASC line: a classic CAN data frame in hex base.

Shape accepted (every other line is handed to the Python parser in ``asc.py``)::

    <ws> 12.345678 <ws> 1 <ws> 18EBFF00x <ws> Rx <ws> d <ws> 8 <ws> 01 02 03 04 05 06 07 08 [anything]
         seconds        ch     id, x=ext      Rx|Tx    d      DLC 0-8  DLC hex bytes (1-2 digits)

A block of whole lines is split into lines and whitespace-separated tokens with numpy, and
the fixed fields of every line are parsed at once (fixed-width character matrices, one
row per line). It never rejects anything itself: a line that does not fit exactly (a
control character, a 3-digit byte, a 33-bit identifier, a CAN FD or error frame, a header)
is marked for the Python parser, which diagnoses damage, so both paths share one set of
rules. numpy only: a log opens without the compiler start-up (about a second) a compiled
kernel would cost, and the scan runs at about 10 MB/s per core.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from app.ingest.readers.text_scan import tokenise

_FLAG_EXT = 1
_FLAG_TX = 64


@dataclass
class BlockScan:
    """Lines of a block and the frames of its fast lines.

    ``starts``/``ends``: byte span of every line (``ends`` excludes the newline); ``fast``: the
    line was parsed here; ``blank``: no token. Frame columns hold one row per fast line, in
    line order; ``t_ns`` is the line's own timestamp (ns).
    """

    starts: npt.NDArray[np.int64]
    ends: npt.NDArray[np.int64]
    fast: npt.NDArray[np.bool_]
    blank: npt.NDArray[np.bool_]
    t_ns: npt.NDArray[np.int64]
    channel: npt.NDArray[np.int64]
    arb_id: npt.NDArray[np.int64]
    flags: npt.NDArray[np.int64]
    dlc: npt.NDArray[np.int64]
    data: npt.NDArray[np.uint8]


def scan_block(block: bytes, hex_base: bool) -> BlockScan:
    """Split ``block`` (whole lines) into lines and parse every line of the accepted shape."""
    tk = tokenise(block)
    tok_start, tok_len, ntok = tk.tok_start, tk.tok_len, tk.ntok
    nlines = tk.ends.size
    empty = np.empty(0, np.int64)
    if not hex_base or not tok_start.size:
        return BlockScan(tk.starts, tk.ends, np.zeros(nlines, bool), tk.blank, empty, empty, empty, empty, empty,
                         np.zeros((0, 8), np.uint8))
    at = tk.at
    cand = np.flatnonzero(tk.clean & (ntok >= 6))
    f = tk.first[cand]
    d_tok, dlc_tok, dir_tok = at(f + 4), at(f + 5), at(f + 3)
    code = tk.char(dlc_tok).astype(np.int64) - 48
    dir_c0, dir_c1 = tk.char(dir_tok), tk.char(dir_tok, 1)
    shape = ((tok_len[dir_tok] == 2) & ((dir_c0 == 82) | (dir_c0 == 84)) & (dir_c1 == 120)
             & tk.equals(d_tok, b"d")
             & (tok_len[dlc_tok] == 1) & (code >= 0) & (code <= 8) & (ntok[cand] >= 6 + code))
    cand, f, code, tx = cand[shape], f[shape], code[shape], dir_c0[shape] == 84
    # channel: 1-4 decimal digits
    channel, ch_ok = tk.decimal(at(f + 1), 4)
    # identifier: 1-8 hex digits, optional x/X, at most 29 bits
    id_tok = at(f + 2)
    last = tk.last_char(id_tok)
    ext = (last == 120) | (last == 88)
    ident, id_ok = tk.hex_value(tok_start[id_tok], tok_len[id_tok] - ext, 8)
    id_ok &= ident <= 0x1FFFFFFF
    t_ns, ts_ok = tk.time_ns(f, 9, dot_required=True)
    # data bytes: tokens f+6 .. f+5+code, 1-2 hex digits each
    data, bytes_ok = tk.data_bytes(f + 6, code)
    good = ch_ok & id_ok & ts_ok & bytes_ok
    fast = np.zeros(nlines, bool)
    fast[cand[good]] = True
    flags = (np.where(ext, _FLAG_EXT, 0) | np.where(tx, _FLAG_TX, 0)).astype(np.int64)
    return BlockScan(tk.starts, tk.ends, fast, tk.blank, t_ns[good], channel[good] - 1, ident[good], flags[good],
                     code[good], data[good])
