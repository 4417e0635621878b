"""Vectorised tokens of a block of text log lines, and their fixed fields parsed at once (numpy only).

A block of whole lines is split into lines and whitespace-separated tokens in a few array
passes; a format's scanner (:mod:`asc_scan`, :mod:`trc_scan`) then picks its fields by token
position and parses every line's field at once from fixed-width character matrices. Every
field parser returns the values and an ``ok`` mask; a scanner never rejects anything itself --
a line that does not fit its shape exactly is left to the format's Python line parser, which
diagnoses damage, so both paths share one set of rules and the scanner is tested against it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

I64 = npt.NDArray[np.int64]
BOOL = npt.NDArray[np.bool_]

HEX = np.full(256, -1, np.int64)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    HEX[_c] = 10 + _i
DIGIT = np.full(256, -1, np.int64)
DIGIT[48:58] = np.arange(10)
_DIGIT8 = DIGIT.astype(np.int8)
_MAX_DIGITS = 9  # whole and fraction digits of a decimal time read here (more: the line parser's)
_TS_OFFSETS = np.array([*range(-_MAX_DIGITS, 0), *range(1, _MAX_DIGITS + 1)], np.int64)  # around the dot


def _ts_weights(scale_exp: int) -> I64:
    """Weights of the digits around the dot for a unit of ``10**scale_exp`` ns; fraction digits past ns weigh 0."""
    return np.array([10 ** (scale_exp - 1 - o) if o < 0 else (10 ** (scale_exp - o) if o <= scale_exp else 0)
                     for o in _TS_OFFSETS.tolist()], np.int64)


@dataclass
class Tokens:
    """Lines and tokens of a block.

    ``starts``/``ends``: byte span of every line (``ends`` excludes the newline); ``first``: index
    of each line's first token, ``ntok`` its token count, ``blank``: no token; ``clean``: no byte
    the line parsers call non-printable (control bytes, a CR not ending the line, C1 controls).
    """

    a: npt.NDArray[np.uint8]
    starts: I64
    ends: I64
    tok_start: I64
    tok_len: I64
    first: I64
    ntok: I64
    blank: BOOL
    clean: BOOL

    def at(self, idx: I64) -> I64:
        """Token indices clipped into range (reading past a line's tokens is masked by the caller's counts)."""
        return np.minimum(idx, max(self.tok_start.size - 1, 0))

    def char(self, idx: I64, k: int = 0) -> npt.NDArray[np.uint8]:
        """The ``k``-th character of tokens ``idx`` (undefined past a token's end: check its length)."""
        return self.a[np.minimum(self.tok_start[idx] + k, self.a.size - 1)]

    def last_char(self, idx: I64) -> npt.NDArray[np.uint8]:
        return self.a[self.tok_start[idx] + self.tok_len[idx] - 1]

    def equals(self, idx: I64, text: bytes) -> BOOL:
        """Tokens ``idx`` that are exactly ``text``."""
        ok = self.tok_len[idx] == len(text)
        for k, c in enumerate(text):
            ok &= self.char(idx, k) == c
        return ok

    def chars(self, start: I64, length: I64, width: int) -> tuple[npt.NDArray[np.uint8], BOOL]:
        """Characters of spans as a ``(spans, width)`` matrix (0 past each span's end) and that mask."""
        k = np.arange(width)
        inside = k[None, :] < length[:, None]
        chars = self.a[np.minimum(start[:, None] + k[None, :], self.a.size - 1)]
        return np.where(inside, chars, 0).astype(np.uint8), inside

    def hex_value(self, start: I64, length: I64, width: int) -> tuple[I64, BOOL]:
        """Value of spans of 1 to ``width`` hex digits; False where a character is not one."""
        return self._number(start, length, width, HEX, 16)

    def decimal(self, idx: I64, width: int) -> tuple[I64, BOOL]:
        """Value of tokens of 1 to ``width`` decimal digits; False elsewhere."""
        return self._number(self.tok_start[idx], self.tok_len[idx], width, DIGIT, 10)

    def _number(self, start: I64, length: I64, width: int, table: I64, base: int) -> tuple[I64, BOOL]:
        """Value of spans of 1 to ``width`` digits of ``base`` (``table``: each byte's digit, -1 for none)."""
        chars, inside = self.chars(start, length, width)
        digit = table[chars]
        ok = np.all((digit >= 0) | ~inside, axis=1) & (length >= 1) & (length <= width)
        place = np.clip(length[:, None] - 1 - np.arange(width)[None, :], 0, width - 1)
        weight = base ** np.arange(width, dtype=np.int64)
        return np.sum(np.where(inside, np.maximum(digit, 0) * weight[place], 0), axis=1), ok

    def time_ns(self, idx: I64, scale_exp: int, *, dot_required: bool) -> tuple[I64, BOOL]:
        """Tokens ``digits{1,9}[.digits{1,9}]`` as integer ns for a unit of ``10**scale_exp`` ns.

        Without ``dot_required`` a token of whole digits only is read too. Fraction digits past
        1 ns are truncated, as the line parsers do.
        """
        start = self.tok_start[idx]
        end = start + self.tok_len[idx]
        dots = np.flatnonzero(self.a == 46)
        i = np.minimum(np.searchsorted(dots, start), max(dots.size - 1, 0))
        dot = dots[i] if dots.size else end
        nxt = dots[np.minimum(i + 1, dots.size - 1)] if dots.size else end
        has_dot = (dot > start) & (dot < end)
        one_dot = (nxt >= end) | (nxt == dot)
        ok = has_dot & one_dot & (dot - start <= _MAX_DIGITS) & (end - dot >= 2) & (end - dot <= _MAX_DIGITS + 1)
        if not dot_required:
            whole = (dot >= end) | (dot < start)  # no dot inside the token
            dot = np.where(whole, end, dot)
            ok |= whole & (end - start >= 1) & (end - start <= _MAX_DIGITS)
        pos = dot[:, None] + _TS_OFFSETS[None, :]
        inside = (pos >= start[:, None]) & (pos < end[:, None])
        digit = _DIGIT8[self.a[np.clip(pos, 0, self.a.size - 1)]]
        digit[~inside] = 0
        ok &= np.all(digit >= 0, axis=1)
        return digit.astype(np.int64) @ _ts_weights(scale_exp), ok

    def data_bytes(self, first: I64, count: I64) -> tuple[npt.NDArray[np.uint8], BOOL]:
        """Up to 8 bytes per line from tokens ``first .. first + count - 1`` of 1-2 hex digits each."""
        size = self.a.size
        k = np.arange(8)[None, :]
        wanted = k < count[:, None]
        btok = self.at(first[:, None] + k)
        bstart, blen = self.tok_start[btok], self.tok_len[btok]
        hi = HEX[self.a[bstart]]
        lo = HEX[self.a[np.minimum(bstart + 1, size - 1)]]
        byte = np.where(blen == 2, hi * 16 + lo, hi)
        ok = np.all(~wanted | ((blen <= 2) & (hi >= 0) & ((blen == 1) | (lo >= 0))), axis=1)
        return np.where(wanted, byte, 0).astype(np.uint8), ok


def tokenise(block: bytes) -> Tokens:
    """Split ``block`` (whole lines) into lines and whitespace-separated tokens."""
    a = np.frombuffer(block, np.uint8)
    size = a.size
    nl = np.flatnonzero(a == 10)
    ends = nl if size and a[-1] == 10 else np.append(nl, size)
    starts = np.concatenate(([0], ends[:-1] + 1)).astype(np.int64)
    tok = a > 32  # space, tab, CR, LF (and control bytes, whose lines the parser takes anyway)
    t8 = tok.view(np.int8)
    # token edges alternate start, end, start, ...: one pass finds both
    edges = np.flatnonzero(t8[1:] != t8[:-1]) + 1
    if size and tok[0]:
        edges = np.concatenate(([0], edges))
    if size and tok[-1]:
        edges = np.append(edges, size)
    tok_start = edges[0::2].astype(np.int64)
    tok_len = (edges[1::2] - tok_start).astype(np.int64)
    first = np.searchsorted(tok_start, starts).astype(np.int64)  # index of each line's first token
    ntok = np.searchsorted(tok_start, ends) - first
    clean = np.ones(ends.size, bool)
    # the bytes that are not token bytes are all blanks unless a control byte hides among them
    blanks = size - int(np.count_nonzero(tok))
    expected = block.count(b" ") + block.count(b"\t") + nl.size + (cr := block.count(b"\r"))
    if blanks != expected or cr or int(a.max(initial=0)) >= 127:
        control = (a < 32) & (a != 9) & (a != 10) & (a != 13) | (a >= 127) & (a <= 160) | (a == 173)
        control |= (a == 13) & (np.append(a[1:], 10) != 10)
        clean[np.searchsorted(ends, np.flatnonzero(control))] = False
    return Tokens(a, ends=ends.astype(np.int64), starts=starts, tok_start=tok_start, tok_len=tok_len, first=first,
                  ntok=ntok.astype(np.int64), blank=ntok == 0, clean=clean)


def block_lines(block: bytes) -> list[bytes]:
    """The lines of a block of whole lines, without their newlines (the line parsers' path)."""
    parts = block.split(b"\n")
    if block.endswith(b"\n"):
        parts.pop()
    return parts


Frame = tuple[int, int, int, int, int, bytes]  # t_ns, channel, arb_id, flags, dlc, payload


def merge_rows(fast_line: I64, cols: list[Any], data: npt.NDArray[np.uint8],
               frames: list[tuple[int, Frame]]) -> tuple[list[Any], npt.NDArray[np.uint8]]:
    """Scanner rows (``fast_line``: their line indices) and line-parser frames as one set of columns in line order."""
    line = np.concatenate([fast_line, np.array([j for j, _ in frames], np.int64)])
    order = np.argsort(line, kind="stable")
    extra = list(zip(*(fr for _, fr in frames), strict=True))
    merged = [np.concatenate([c, np.array(e, np.int64)])[order] for c, e in zip(cols, extra[:5], strict=True)]
    width = max([data.shape[1], *(len(p) for p in extra[5])])
    wide = np.zeros((len(line), width), np.uint8)
    wide[:len(data), :data.shape[1]] = data
    for k, payload in enumerate(extra[5]):
        wide[len(data) + k, :len(payload)] = np.frombuffer(payload, np.uint8)
    return merged, wide[order]
