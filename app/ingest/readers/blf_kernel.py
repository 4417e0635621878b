"""Compiled object-by-object walk over decompressed BLF container bytes (the diagnosing fallback).

The vectorised fast path (:mod:`blf_vector`) handles healthy containers; this kernel runs
when it declines. It decodes CAN objects straight into a
:class:`~app.ingest.readers._base.ChunkBuilder`'s columns and stops at the first thing it
cannot vouch for, returning a status and the byte position; the Python driver (``blf.py``)
reports, resynchronises and calls it again. Every path either advances ``pos`` or
returns, so the walk cannot loop forever. Layouts: :mod:`blf_layout`.
"""

from __future__ import annotations

from typing import Any

import numba
import numpy as np

from app.ingest.readers.blf_layout import (
    CAN_ERROR,
    CAN_ERROR_EXT,
    CAN_FD_ERROR_64,
    CAN_FD_MESSAGE,
    CAN_FD_MESSAGE_64,
    CAN_MESSAGE,
    CAN_MESSAGE2,
    MAX_OBJECT_SIZE,
    ST_BAD_FRAME,
    ST_BAD_HEADER,
    ST_BAD_SIG,
    ST_BAD_SIZE,
    ST_BAD_TS,
    ST_END,
    ST_FULL,
)

_SIG = 0x4A424F4C  # b"LOBJ" little endian
_I64_MAX = 9223372036854775807
_MAX_10US = _I64_MAX // 10000

_FLAG_EXT = 1
_FLAG_FD = 2
_FLAG_ERR = 4
_FLAG_RTR = 8
_FLAG_BRS = 16
_FLAG_ESI = 32
_FLAG_TX = 64

_DLC_LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64], np.int64)


@numba.njit(inline="always")
def _u8(b: np.ndarray, p: int) -> Any:
    return np.int64(b[p])


@numba.njit(inline="always")
def _u16(b: np.ndarray, p: int) -> Any:  # numba types it int64
    return np.int64(b[p]) | (np.int64(b[p + 1]) << 8)


@numba.njit(inline="always")
def _u32(b: np.ndarray, p: int) -> Any:  # int64 (unsigned mixes would promote to float)
    return (np.int64(b[p]) | (np.int64(b[p + 1]) << 8) | (np.int64(b[p + 2]) << 16)
            | (np.int64(b[p + 3]) << 24))


@numba.njit(inline="always")
def _dlc_len(code: int) -> Any:
    return _DLC_LEN[code] if code <= 15 else 64


@numba.njit(inline="always")
def _payload_bounds(otype: int) -> tuple[int, int]:
    """Plausible payload sizes per CAN type; CAN_MESSAGE is fixed ("extension not allowed")."""
    if otype == CAN_MESSAGE:
        return 16, 16
    if otype == CAN_ERROR:
        return 4, 16
    if otype == CAN_ERROR_EXT:
        return 32, 64
    if otype == CAN_MESSAGE2:
        return 16, 64
    if otype == CAN_FD_MESSAGE:
        return 20, 256
    if otype == CAN_FD_MESSAGE_64:
        return 40, 512
    if otype == CAN_FD_ERROR_64:
        return 44, 512
    return 0, MAX_OBJECT_SIZE


@numba.njit(inline="always")
def _sig_at(b: np.ndarray, p: int) -> bool:
    return b[p] == 0x4C and b[p + 1] == 0x4F and b[p + 2] == 0x42 and b[p + 3] == 0x4A


@numba.njit(cache=True, nogil=True)
def walk_objects(buf: np.ndarray, pos: int, end: int,
                 t_ns: np.ndarray, channel: np.ndarray, arb_id: np.ndarray, flags: np.ndarray,
                 dlc: np.ndarray, data: np.ndarray, n: int, cap: int,
                 type_counts: np.ndarray) -> tuple[int, int, int, int]:
    """Decode objects in ``buf[pos:end]`` into rows ``n..cap-1``; return ``(status, pos, n, detail)``.

    ``type_counts[min(type, 255)]`` counts the non-CAN objects that were skipped.
    """
    while True:
        if n >= cap:
            return ST_FULL, pos, n, 0
        if pos + 4 > end:
            return ST_END, pos, n, 0
        if not _sig_at(buf, pos):
            found = -1
            for k in range(1, 4):
                if pos + k + 4 > end:
                    return ST_END, pos, n, 0
                if _sig_at(buf, pos + k):
                    found = pos + k
                    break
            if found < 0:
                return ST_BAD_SIG, pos, n, 0
            pos = found
        if pos + 16 > end:
            return ST_END, pos, n, 0
        hsize = _u16(buf, pos + 4)
        hver = _u16(buf, pos + 6)
        size = _u32(buf, pos + 8)
        otype = _u32(buf, pos + 12)
        if hver == 1:
            hmin = 32
        elif hver == 2:
            hmin = 40
        else:
            return ST_BAD_HEADER, pos, n, hver
        if hsize < hmin or hsize > hmin + 64:
            return ST_BAD_HEADER, pos, n, hver
        if size < hsize or size > MAX_OBJECT_SIZE:
            return ST_BAD_SIZE, pos, n, size
        lo, hi = _payload_bounds(otype)
        if size - hsize < lo or size - hsize > hi:
            return ST_BAD_SIZE, pos, n, size
        if pos + size > end:
            return ST_END, pos, n, 0
        nxt = pos + size
        if otype != CAN_MESSAGE and nxt + 7 <= end:
            # a size that does not land on the next signature is corrupt (fixed-size CAN_MESSAGE
            # needs no check: if the next signature is missing, the next object is the damaged one)
            ok = False
            for k in range(4):
                if _sig_at(buf, nxt + k):
                    ok = True
                    break
            if not ok:
                return ST_BAD_SIZE, pos, n, size
        if otype not in (CAN_MESSAGE, CAN_MESSAGE2, CAN_FD_MESSAGE, CAN_FD_MESSAGE_64, CAN_ERROR_EXT, CAN_ERROR,
                         CAN_FD_ERROR_64):
            type_counts[min(otype, 255)] += 1
            pos = nxt
            continue
        oflags = _u32(buf, pos + 16)
        ts_lo = _u32(buf, pos + 24)
        ts_hi = _u32(buf, pos + 28)
        if ts_hi >= 0x80000000:
            return ST_BAD_TS, pos, n, size
        ts = (ts_hi << 32) | ts_lo
        if oflags == 1:  # 10 us units (python-can treats every other value as ns)
            if ts > _MAX_10US:
                return ST_BAD_TS, pos, n, size
            ts *= 10000
        p = pos + hsize
        avail = size - hsize
        fl = 0
        if otype in (CAN_MESSAGE, CAN_MESSAGE2):
            ch = _u16(buf, p) - 1
            f8 = buf[p + 2]
            code = _u8(buf, p + 3)
            ident = _u32(buf, p + 4)
            nbytes = min(code, 8)
            if f8 & 0x80:
                fl |= _FLAG_RTR
                nbytes = 0
            if f8 & 0x01:
                fl |= _FLAG_TX
            length = code
            src = p + 8
        elif otype == CAN_FD_MESSAGE:
            ch = _u16(buf, p) - 1
            f8 = buf[p + 2]
            code = _u8(buf, p + 3)
            ident = _u32(buf, p + 4)
            fdf = buf[p + 13]
            nbytes = _u8(buf, p + 14)
            if nbytes > 64:
                return ST_BAD_FRAME, pos, n, size
            nbytes = min(nbytes, avail - 20)
            if fdf & 0x1:
                fl |= _FLAG_FD
            if fdf & 0x2:
                fl |= _FLAG_BRS
            if fdf & 0x4:
                fl |= _FLAG_ESI
            if f8 & 0x80:
                fl |= _FLAG_RTR
                nbytes = 0
            if f8 & 0x01:
                fl |= _FLAG_TX
            length = _dlc_len(code)
            src = p + 20
        elif otype == CAN_FD_MESSAGE_64:
            ch = _u8(buf, p) - 1
            code = _u8(buf, p + 1)
            valid = _u8(buf, p + 2)
            ident = _u32(buf, p + 4)
            f32 = _u32(buf, p + 12)
            direction = buf[p + 34]
            ext_off = _u8(buf, p + 35)
            if valid > 64:
                return ST_BAD_FRAME, pos, n, size
            # the data field may be shorter than ``valid`` (python-can issue 1905): zero-pad
            stop = ext_off if ext_off != 0 else size
            nbytes = max(0, min(valid, stop - hsize - 40))
            if f32 & 0x0010:
                fl |= _FLAG_RTR
            if f32 & 0x1000:
                fl |= _FLAG_FD
            if f32 & 0x2000:
                fl |= _FLAG_BRS
            if f32 & 0x4000:
                fl |= _FLAG_ESI
            if direction != 0:
                fl |= _FLAG_TX
            length = _dlc_len(code)
            src = p + 40
            if fl & _FLAG_RTR:
                nbytes = 0
        elif otype == CAN_ERROR_EXT:
            ch = _u16(buf, p) - 1
            code = _u8(buf, p + 10)
            ident = _u32(buf, p + 16)
            fl |= _FLAG_ERR
            nbytes = min(code, 8)
            length = code
            src = p + 24
        elif otype == CAN_ERROR:
            ch = _u16(buf, p) - 1
            ident = 0
            fl |= _FLAG_ERR
            nbytes = 0
            length = 0
            src = p
        else:  # CAN_FD_ERROR_64
            ch = _u8(buf, p) - 1
            code = _u8(buf, p + 1)
            valid = _u8(buf, p + 2)
            ident = _u32(buf, p + 12)
            if valid > 64:
                return ST_BAD_FRAME, pos, n, size
            fl |= _FLAG_ERR | _FLAG_FD
            nbytes = max(0, min(valid, avail - 44))
            length = _dlc_len(code & 0xF)
            src = p + 44
        if ident & 0x80000000:
            fl |= _FLAG_EXT
        t_ns[n] = ts
        channel[n] = ch if -32768 <= ch <= 32767 else -1
        arb_id[n] = ident & 0x1FFFFFFF
        flags[n] = fl
        dlc[n] = length
        for k in range(nbytes):
            data[n, k] = buf[src + k]
        n += 1
        pos = nxt
