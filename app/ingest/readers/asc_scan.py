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

_FLAG_EXT = 1
_FLAG_TX = 64

_HEX = np.full(256, -1, np.int64)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _HEX[_c] = 10 + _i
_DIGIT = np.full(256, -1, np.int64)
_DIGIT[48:58] = np.arange(10)
_DIGIT8 = _DIGIT.astype(np.int8)
_POW10 = 10 ** np.arange(19, dtype=np.int64)
_TS_OFFSETS = np.array([*range(-9, 0), *range(1, 10)], np.int64)  # around the dot: 9 whole, 9 fraction digits
_TS_WEIGHTS = np.array([10 ** (9 - o) if o > 0 else 10 ** (8 - o) for o in _TS_OFFSETS.tolist()], np.int64)


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


def _chars(a: npt.NDArray[np.uint8], start: npt.NDArray[np.int64], length: npt.NDArray[np.int64],
           width: int) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.bool_]]:
    """Characters of tokens as a ``(tokens, width)`` matrix (0 past each token's end) and that mask."""
    k = np.arange(width)
    inside = k[None, :] < length[:, None]
    chars = a[np.minimum(start[:, None] + k[None, :], a.size - 1)]
    return np.where(inside, chars, 0).astype(np.uint8), inside


def _hex_value(a: npt.NDArray[np.uint8], start: npt.NDArray[np.int64], length: npt.NDArray[np.int64],
               width: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """Value of tokens of at most ``width`` hex digits; False where a character is not one."""
    chars, inside = _chars(a, start, length, width)
    digit = _HEX[chars]
    ok = np.all((digit >= 0) | ~inside, axis=1) & (length >= 1) & (length <= width)
    shift = np.clip(length[:, None] - 1 - np.arange(width)[None, :], 0, None) * 4
    value = np.sum(np.where(inside, np.maximum(digit, 0) << shift, 0), axis=1)
    return value, ok


def _timestamps(a: npt.NDArray[np.uint8], dots: npt.NDArray[np.int64], start: npt.NDArray[np.int64],
                end: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """``digits{1,9} . digits{1,9}`` as integer ns, read around the token's dot (``dots``: every '.' of the block)."""
    i = np.minimum(np.searchsorted(dots, start), max(dots.size - 1, 0))
    dot = dots[i] if dots.size else start
    nxt = dots[np.minimum(i + 1, dots.size - 1)] if dots.size else start
    ok = (dot > start) & (dot - start <= 9) & (end - dot >= 2) & (end - dot <= 10) & ((nxt >= end) | (nxt == dot))
    pos = dot[:, None] + _TS_OFFSETS[None, :]
    inside = (pos >= start[:, None]) & (pos < end[:, None])
    digit = _DIGIT8[a[np.clip(pos, 0, a.size - 1)]]
    digit[~inside] = 0
    ok &= np.all(digit >= 0, axis=1)
    return digit.astype(np.int64) @ _TS_WEIGHTS, ok


def scan_block(block: bytes, hex_base: bool) -> BlockScan:
    """Split ``block`` (whole lines) into lines and parse every line of the accepted shape."""
    a = np.frombuffer(block, np.uint8)
    size = a.size
    nl = np.flatnonzero(a == 10)
    ends = nl if size and a[-1] == 10 else np.append(nl, size)
    starts = np.concatenate(([0], ends[:-1] + 1)).astype(np.int64)
    nlines = ends.size
    tok = a > 32  # space, tab, CR, LF (and control bytes, whose lines the parser takes anyway)
    t8 = tok.view(np.int8)
    # token edges alternate start, end, start, ...: one pass finds both
    edges = np.flatnonzero(t8[1:] != t8[:-1]) + 1
    if size and tok[0]:
        edges = np.concatenate(([0], edges))
    if size and tok[-1]:
        edges = np.append(edges, size)
    tok_start = edges[0::2]
    tok_len = edges[1::2] - tok_start
    first = np.searchsorted(tok_start, starts)  # index of each line's first token
    ntok = np.searchsorted(tok_start, ends) - first
    blank = ntok == 0
    empty = np.empty(0, np.int64)
    if not hex_base or not tok_start.size:
        return BlockScan(starts, ends, np.zeros(nlines, bool), blank, empty, empty, empty, empty, empty,
                         np.zeros((0, 8), np.uint8))
    # lines with a byte the parser calls non-printable (or a CR not ending the line) are the parser's
    clean = np.ones(nlines, bool)
    # the bytes that are not token bytes are all blanks unless a control byte hides among them
    blanks = size - int(np.count_nonzero(tok))
    expected = block.count(b" ") + block.count(b"\t") + nl.size + (cr := block.count(b"\r"))
    if blanks != expected or cr or int(a.max(initial=0)) >= 127:
        control = (a < 32) & (a != 9) & (a != 10) & (a != 13) | (a >= 127) & (a <= 160) | (a == 173)
        control |= (a == 13) & (np.append(a[1:], 10) != 10)
        clean[np.searchsorted(ends, np.flatnonzero(control))] = False

    def at(idx: npt.NDArray[np.int64]) -> npt.NDArray[np.int64]:
        return np.minimum(idx, tok_start.size - 1)

    cand = np.flatnonzero(clean & (ntok >= 6))
    f = first[cand]
    d_tok, dlc_tok, dir_tok = at(f + 4), at(f + 5), at(f + 3)
    dlc_char = a[tok_start[dlc_tok]]
    code = dlc_char.astype(np.int64) - 48
    dir_c0, dir_c1 = a[tok_start[dir_tok]], a[np.minimum(tok_start[dir_tok] + 1, size - 1)]
    shape = ((tok_len[dir_tok] == 2) & ((dir_c0 == 82) | (dir_c0 == 84)) & (dir_c1 == 120)
             & (tok_len[d_tok] == 1) & (a[tok_start[d_tok]] == 100)
             & (tok_len[dlc_tok] == 1) & (code >= 0) & (code <= 8) & (ntok[cand] >= 6 + code))
    cand, f, code, tx = cand[shape], f[shape], code[shape], dir_c0[shape] == 84
    # channel: 1-4 decimal digits
    ch_tok = at(f + 1)
    ch_chars, ch_in = _chars(a, tok_start[ch_tok], tok_len[ch_tok], 4)
    ch_digit = _DIGIT[ch_chars]
    ch_ok = (tok_len[ch_tok] <= 4) & np.all((ch_digit >= 0) | ~ch_in, axis=1)
    ch_shift = np.clip(tok_len[ch_tok][:, None] - 1 - np.arange(4)[None, :], 0, 3)
    channel = np.sum(np.where(ch_in, np.maximum(ch_digit, 0) * _POW10[ch_shift], 0), axis=1)
    # identifier: 1-8 hex digits, optional x/X, at most 29 bits
    id_tok = at(f + 2)
    id_start, id_len = tok_start[id_tok], tok_len[id_tok]
    last = a[id_start + id_len - 1]
    ext = (last == 120) | (last == 88)
    ident, id_ok = _hex_value(a, id_start, id_len - ext, 8)
    id_ok &= ident <= 0x1FFFFFFF
    t_ns, ts_ok = _timestamps(a, np.flatnonzero(a == 46), tok_start[f], tok_start[f] + tok_len[f])
    # data bytes: tokens f+6 .. f+5+code, 1-2 hex digits each
    k = np.arange(8)[None, :]
    wanted = k < code[:, None]
    btok = at(f[:, None] + 6 + k)
    bstart, blen = tok_start[btok], tok_len[btok]
    hi = _HEX[a[bstart]]
    lo = _HEX[a[np.minimum(bstart + 1, size - 1)]]
    byte = np.where(blen == 2, hi * 16 + lo, hi)
    bytes_ok = np.all(~wanted | ((blen <= 2) & (hi >= 0) & ((blen == 1) | (lo >= 0))), axis=1)
    good = ch_ok & id_ok & ts_ok & bytes_ok
    fast = np.zeros(nlines, bool)
    fast[cand[good]] = True
    data = np.where(wanted, byte, 0)[good].astype(np.uint8)
    flags = np.where(ext, _FLAG_EXT, 0) | np.where(tx, _FLAG_TX, 0)
    return BlockScan(starts, ends, fast, blank, t_ns[good], channel[good] - 1, ident[good], flags[good],
                     code[good], data)
