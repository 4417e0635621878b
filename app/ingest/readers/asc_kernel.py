"""Compiled fast path for the common Vector ASC line: a classic CAN data frame in hex base.

Shape accepted (anything else is handed back to the Python parser in ``asc.py``)::

    <ws> 12.345678 <ws> 1 <ws> 18EBFF00x <ws> Rx <ws> d <ws> 8 <ws> 01 02 03 04 05 06 07 08 [anything]
         seconds        ch     id, x=ext      Rx|Tx    d      DLC 0-8  exactly DLC hex bytes (1-2 digits)

The kernel walks line by line, writes accepted frames straight into a chunk builder's
columns and stops at the first other non-blank line (``ST_SLOW``), returning its span and
number. It never rejects anything itself: damaged lines are diagnosed by the Python
parser, so both paths share one set of rules. Every iteration advances ``pos``.
"""

from __future__ import annotations

import numba
import numpy as np

ST_END = 0  # all lines up to ``end`` consumed
ST_FULL = 1  # output columns full; ``pos`` is the next line
ST_SLOW = 2  # line ``line_no`` spans ``buf[pos:eol]`` and needs the Python parser

_FLAG_EXT = 1
_FLAG_TX = 64


_HEX = np.full(256, -1, np.int64)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _HEX[_c] = 10 + _i


@numba.njit(inline="always")
def _ws(c: int) -> bool:
    return c == 32 or c == 9


@numba.njit(cache=True, nogil=True)
def scan_lines(buf: np.ndarray, pos: int, end: int, line_no: int,
               relative: bool, t_acc: int, t_ns: np.ndarray, channel: np.ndarray, arb_id: np.ndarray,
               flags: np.ndarray, dlc: np.ndarray, data: np.ndarray, n: int,
               cap: int) -> tuple[int, int, int, int, int, int]:
    """Parse lines of ``buf[pos:end]``; return ``(status, pos, line_no, n, t_acc, eol)``.

    ``line_no`` is the number of the line before ``pos``; ``t_acc`` the running time of the
    previous event in relative-timestamp mode (ns). Each byte is visited once: fields are
    parsed left to right and only the rest of the line is scanned for its end.
    """
    tmp = np.zeros(8, np.uint8)
    while pos < end:
        if n >= cap:
            return ST_FULL, pos, line_no, n, t_acc, pos
        line_no += 1
        i = pos
        while i < end and _ws(buf[i]):
            i += 1
        ok = False
        blank = i >= end or buf[i] == 10 or buf[i] == 13
        # -- timestamp: up to 9 integer digits, '.', fraction (digits past ns truncated)
        whole = 0
        nd = 0
        while i < end and 48 <= buf[i] <= 57 and nd < 10:
            whole = whole * 10 + (buf[i] - 48)
            nd += 1
            i += 1
        if 0 < nd <= 9 and i < end and buf[i] == 46:
            i += 1
            frac = 0
            fd = 0
            while i < end and 48 <= buf[i] <= 57:
                if fd < 9:
                    frac = frac * 10 + (buf[i] - 48)
                fd += 1
                i += 1
            if fd > 0 and i < end and _ws(buf[i]):
                for _ in range(min(fd, 9), 9):
                    frac *= 10
                ts = whole * 1000000000 + frac
                while i < end and _ws(buf[i]):
                    i += 1
                # -- channel: decimal
                ch = 0
                nd = 0
                while i < end and 48 <= buf[i] <= 57 and nd < 6:
                    ch = ch * 10 + (buf[i] - 48)
                    nd += 1
                    i += 1
                if 0 < nd <= 4 and i < end and _ws(buf[i]):
                    while i < end and _ws(buf[i]):
                        i += 1
                    # -- identifier: 1..8 hex digits, optional x
                    ident = 0
                    nh = 0
                    while i < end and _HEX[buf[i]] >= 0 and nh < 9:
                        ident = ident * 16 + _HEX[buf[i]]
                        nh += 1
                        i += 1
                    fl = 0
                    if i < end and (buf[i] == 120 or buf[i] == 88):
                        fl |= _FLAG_EXT
                        i += 1
                    if 0 < nh <= 8 and i < end and _ws(buf[i]):
                        while i < end and _ws(buf[i]):
                            i += 1
                        # -- direction Rx/Tx, then 'd'
                        if (i + 2 < end and buf[i + 1] == 120 and (buf[i] == 82 or buf[i] == 84)
                                and _ws(buf[i + 2])):
                            if buf[i] == 84:
                                fl |= _FLAG_TX
                            i += 2
                            while i < end and _ws(buf[i]):
                                i += 1
                            if i + 1 < end and buf[i] == 100 and _ws(buf[i + 1]):
                                i += 1
                                while i < end and _ws(buf[i]):
                                    i += 1
                                code = _HEX[buf[i]] if i < end else -1
                                if 0 <= code <= 8 and (i + 1 >= end or _ws(buf[i + 1]) or buf[i + 1] == 10
                                                       or buf[i + 1] == 13):
                                    i += 1
                                    good = True
                                    for k in range(code):
                                        while i < end and _ws(buf[i]):
                                            i += 1
                                        if i >= end or _HEX[buf[i]] < 0:
                                            good = False
                                            break
                                        v = _HEX[buf[i]]
                                        i += 1
                                        if i < end and _HEX[buf[i]] >= 0:
                                            v = v * 16 + _HEX[buf[i]]
                                            i += 1
                                        if i < end and not (_ws(buf[i]) or buf[i] == 10 or buf[i] == 13):
                                            good = False
                                            break
                                        tmp[k] = v
                                    if good:
                                        if relative:
                                            t_acc += ts
                                            ts = t_acc
                                        t_ns[n] = ts
                                        channel[n] = ch - 1
                                        arb_id[n] = ident
                                        flags[n] = fl
                                        dlc[n] = code
                                        for k in range(code):
                                            data[n, k] = tmp[k]
                                        n += 1
                                        ok = True
        eol = i
        while eol < end and buf[eol] != 10:
            eol += 1
        if not ok and not blank:
            return ST_SLOW, pos, line_no, n, t_acc, eol
        pos = eol + 1
    return ST_END, pos, line_no, n, t_acc, pos
