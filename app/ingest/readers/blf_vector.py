"""Vectorised decoding of a whole BLF container at once (numpy only; the fast path).

A healthy container is a gap-free chain of objects: every object starts with ``LOBJ`` at
most 3 padding bytes after the previous one ends. :func:`decode_run` finds all signature
candidates with array comparisons, checks that they form exactly that chain and that
every header is plausible, and then gathers the fixed-layout CAN payloads with structured
views. Anything unusual (damage, a stray ``LOBJ`` inside a payload, impossible values)
returns ``None`` and the caller falls back to the compiled object-by-object walk in
:mod:`blf_kernel`, which diagnoses and reports. Layouts: :mod:`blf_layout`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import as_strided

from app.ingest.readers import blf_layout as K

_HEADER = np.dtype([("sig", "<u4"), ("hsize", "<u2"), ("hver", "<u2"), ("size", "<u4"), ("type", "<u4"),
                    ("oflags", "<u4"), ("client", "<u2"), ("over", "<u2"), ("ts", "<u8")])
_CAN = np.dtype([("ch", "<u2"), ("fl", "u1"), ("dlc", "u1"), ("id", "<u4"), ("data", "u1", 8)])
_CAN_FD = np.dtype([("ch", "<u2"), ("fl", "u1"), ("dlc", "u1"), ("id", "<u4"), ("flen", "<u4"), ("arb_bits", "u1"),
                    ("fdf", "u1"), ("valid", "u1"), ("r1", "u1"), ("r2", "<u4"), ("data", "u1", 64)])
_CAN_FD64 = np.dtype([("ch", "u1"), ("dlc", "u1"), ("valid", "u1"), ("txc", "u1"), ("id", "<u4"), ("flen", "<u4"),
                      ("flags", "<u4"), ("btr_arb", "<u4"), ("btr_data", "<u4"), ("brs_ns", "<u4"),
                      ("crc_del_ns", "<u4"), ("bits", "<u2"), ("dir", "u1"), ("ext_off", "u1"), ("crc", "<u4"),
                      ("data", "u1", 64)])
_ERR_EXT = np.dtype([("ch", "<u2"), ("len", "<u2"), ("fl", "<u4"), ("ecc", "u1"), ("pos", "u1"), ("dlc", "u1"),
                     ("r1", "u1"), ("flen", "<u4"), ("id", "<u4"), ("flext", "<u2"), ("r2", "<u2"), ("data", "u1", 8)])
_ERR = np.dtype([("ch", "<u2"), ("len", "<u2")])
_FD_ERR64 = np.dtype([("ch", "u1"), ("dlc", "u1"), ("valid", "u1"), ("ecc", "u1"), ("fl", "<u2"), ("code_ext", "<u2"),
                      ("ext_flags", "<u2"), ("ext_off", "u1"), ("r1", "u1"), ("id", "<u4"), ("rest", "u1", 28),
                      ("data", "u1", 64)])

_IS_FRAME = np.zeros(256, bool)
_IS_FRAME[sorted(K.FRAME_TYPES)] = True
_IS_WIDE = np.zeros(256, bool)
_IS_WIDE[[K.CAN_FD_MESSAGE, K.CAN_FD_MESSAGE_64, K.CAN_FD_ERROR_64]] = True
_DLC_LEN = np.array([0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 16, 20, 24, 32, 48, 64] + [64] * 240, np.int64)
# payload bounds by type (index = type for frame types; others: any size up to the global limit)
_PAY_MIN = np.zeros(256, np.int64)
_PAY_MAX = np.full(256, K.MAX_OBJECT_SIZE, np.int64)
for _t, (_lo, _hi) in {K.CAN_MESSAGE: (16, 16), K.CAN_ERROR: (4, 16), K.CAN_ERROR_EXT: (32, 64),
                       K.CAN_MESSAGE2: (16, 64), K.CAN_FD_MESSAGE: (20, 256), K.CAN_FD_MESSAGE_64: (40, 512),
                       K.CAN_FD_ERROR_64: (44, 512)}.items():
    _PAY_MIN[_t], _PAY_MAX[_t] = _lo, _hi

EXT, FD, ERR, RTR, BRS, ESI, TX = 1, 2, 4, 8, 16, 32, 64
_I64_MAX = np.uint64(2**63 - 1)
_MAX_10US = np.uint64((2**63 - 1) // 10000)
_UNIFORM = {
    size: np.dtype({"names": ["h0", "h1", "oflags", "ts", "ch", "fl", "dlc", "id", "data"],
                    "formats": ["<u8", "<u8", "<u4", "<u8", "<u2", "u1", "u1", "<u4", ("u1", 8)],
                    "offsets": [0, 8, 16, 24, 32, 34, 35, 36, 40], "itemsize": size})
    for size in (48, 56)
}


@dataclass(slots=True)
class Decoded:
    """Frames of one container run, in object order, plus where the unconsumed tail starts."""

    t_ns: npt.NDArray[np.int64]
    channel: npt.NDArray[np.int64]
    arb_id: npt.NDArray[np.int64]
    flags: npt.NDArray[np.int64]
    dlc: npt.NDArray[np.int64]
    data: npt.NDArray[np.uint8]  # (n, 8) or (n, 64), zero beyond each frame's bytes
    end: int  # start of the incomplete remainder (carried into the next container)
    type_counts: npt.NDArray[np.int64]  # skipped non-CAN objects by min(type, 255)


_PAD = 128  # zero bytes appended so fixed-size windows near the end stay inside the array


def _gather(arr: npt.NDArray[np.uint8], pos: npt.NDArray[np.int64], dtype: np.dtype) -> np.ndarray:
    """Records of ``dtype`` starting at byte positions ``pos`` (a row take over a strided window view).

    ``arr`` carries ``_PAD`` trailing zero bytes, so windows may run past the real data.
    """
    width = dtype.itemsize
    windows = as_strided(arr, shape=(len(arr) - width + 1, width), strides=(1, 1), writeable=False)
    return np.ascontiguousarray(windows[pos]).view(dtype)[:, 0]


def _nothing(end: int) -> Decoded:
    empty = np.empty(0, np.int64)
    return Decoded(empty, empty, empty, empty, empty, np.zeros((0, 8), np.uint8), end, np.zeros(256, np.int64))


def decode_run(buf: bytes, start: int) -> Decoded | None:
    """Decode all complete objects of ``buf[start:]``, or None when the fallback walker is needed.

    A leading run of identical classic CAN objects (the bulk of real logs) is read through
    one strided structured view; whatever follows goes through the general gather path.
    """
    head = _uniform_run(buf, start)
    if head is not None and (head.end >= len(buf) - 3 or _incomplete_tail(buf, head.end)):
        return head
    rest_start = head.end if head is not None else start
    rest = _decode_general(buf[rest_start:], 0)
    if rest is None:
        return None
    rest.end += rest_start
    if head is None:
        return rest
    parts = (head, rest)
    width = max(p.data.shape[1] for p in parts)
    data = np.zeros((len(head.t_ns) + len(rest.t_ns), width), np.uint8)
    data[: len(head.t_ns), : head.data.shape[1]] = head.data
    data[len(head.t_ns):, : rest.data.shape[1]] = rest.data
    def cat(field: str) -> npt.NDArray[np.int64]:
        return np.concatenate([getattr(p, field) for p in parts])

    return Decoded(cat("t_ns"), cat("channel"), cat("arb_id"), cat("flags"), cat("dlc"), data, rest.end,
                   head.type_counts + rest.type_counts)


def _incomplete_tail(buf: bytes, pos: int) -> bool:
    """True when ``buf[pos:]`` is just the start of one plausible object (carried to the next container)."""
    j = buf.find(b"LOBJ", pos, pos + 7)
    if j < 0 or j - pos > 3:
        return False
    if len(buf) - j < 16:
        return True
    hsize, hver, size, otype = struct.unpack_from("<HHLL", buf, j + 4)
    t = min(otype, 255)
    return (j + size > len(buf) and hver in (1, 2) and hsize in (32, 40)
            and _PAY_MIN[t] <= size - hsize <= _PAY_MAX[t] and size <= K.MAX_OBJECT_SIZE)


def _uniform_run(buf: bytes, start: int) -> Decoded | None:
    """The leading run of same-size v1 CAN_MESSAGE / CAN_MESSAGE2 objects, decoded via a strided view."""
    first = buf.find(b"LOBJ", start, start + 7)
    if first < 0 or first - start > 3 or len(buf) - first < 48:
        return None
    hsize, hver, size, otype = struct.unpack_from("<HHLL", buf, first + 4)
    if hsize != 32 or hver != 1 or (otype, size) not in ((K.CAN_MESSAGE, 48), (K.CAN_MESSAGE2, 48),
                                                         (K.CAN_MESSAGE2, 56)):
        return None
    count = (len(buf) - first) // size
    view = np.ndarray((count,), _UNIFORM[size], buffer=buf, offset=first, strides=(size,))
    ten_us = view["oflags"] == 1
    ts = view["ts"]
    # the 16-byte base header (signature, sizes, version, type) repeats exactly in a uniform run
    h0, h1 = view["h0"], view["h1"]
    ok = (h0 == h0[0]) & (h1 == h1[0])
    if count and ts.max() > _MAX_10US:
        ok &= ts <= np.where(ten_us, _MAX_10US, _I64_MAX)
    n = count if ok.all() else int(np.argmin(ok))
    if n == 0:
        return None
    view, ten_us, ts = view[:n], ten_us[:n], ts[:n]
    t_ns = np.where(ten_us, ts.astype(np.int64) * 10000, ts.astype(np.int64))
    f8 = view["fl"]
    remote = (f8 & 0x80) != 0
    code = view["dlc"].astype(np.int64)
    ident = view["id"].astype(np.int64)
    fl = (np.where(remote, RTR, 0) | np.where(f8 & 1, TX, 0) | np.where(ident & 0x80000000, EXT, 0)).astype(np.int64)
    ch = view["ch"].astype(np.int64) - 1
    data = np.array(view["data"])
    nbytes = np.where(remote, 0, np.minimum(code, 8))
    data[np.arange(8)[None, :] >= nbytes[:, None]] = 0
    return Decoded(t_ns, np.where(ch > 32767, -1, ch), ident & 0x1FFFFFFF, fl, code, data, first + n * size,
                   np.zeros(256, np.int64))


def _decode_general(buf: bytes, start: int) -> Decoded | None:
    """Gather-based decoding of any mix of objects (see :func:`decode_run`)."""
    size_all = len(buf)
    if size_all - start < 4:
        return _nothing(start)
    arr = np.zeros(size_all + _PAD, np.uint8)
    arr[:size_all] = np.frombuffer(buf, np.uint8)
    a = arr[start:size_all]
    idx = np.flatnonzero(a[:-3] == 0x4C)
    idx = idx[(a[idx + 1] == 0x4F) & (a[idx + 2] == 0x42) & (a[idx + 3] == 0x4A)] + start
    base = idx[idx + 16 <= size_all]  # candidates whose base header is complete
    hdr = _gather(arr, base, _HEADER)
    size = hdr["size"].astype(np.int64)
    complete = base + size <= size_all
    n_obj = len(base) if complete.all() else int(np.argmin(complete))
    # the complete objects plus the incomplete one after them (its header must be sane too: it is carried)
    checked = min(n_obj + 1, len(base))
    objs, ends = base[:n_obj], base[:n_obj] + size[:n_obj]
    if n_obj and not 0 <= objs[0] - start <= 3:
        return None
    if n_obj > 1 and np.any((objs[1:] < ends[:-1]) | (objs[1:] - ends[:-1] > 3)):
        return None
    tail = int(ends[-1]) if n_obj else start
    after = idx[idx >= tail]
    if (after[0] - tail > 3) if len(after) else (size_all - tail > 6):
        return None  # bytes after the last object that are neither padding nor the next signature
    if checked == 0:
        return _nothing(tail)
    h = hdr[:checked]
    size = size[:checked]
    hsize = h["hsize"].astype(np.int64)
    hver = h["hver"].astype(np.int64)
    otype = h["type"].astype(np.int64)
    hmin = np.where(hver == 1, 32, 40)
    tcap = np.minimum(otype, 255)
    pay = size - hsize
    if (np.any((hver != 1) & (hver != 2)) or np.any((hsize < hmin) | (hsize > hmin + 64))
            or np.any((pay < _PAY_MIN[tcap]) | (pay > _PAY_MAX[tcap])) or np.any(size > K.MAX_OBJECT_SIZE)):
        return None
    if n_obj == 0:
        return _nothing(tail)
    size, hsize, otype, tcap = size[:n_obj], hsize[:n_obj], otype[:n_obj], tcap[:n_obj]
    is_frame = _IS_FRAME[tcap] & (otype < 256)
    type_counts = np.bincount(tcap[~is_frame], minlength=256)
    f_pos, f_type, f_h, f_size = objs[is_frame], otype[is_frame], hsize[is_frame], size[is_frame]
    n = len(f_pos)
    stamp = hdr[:n_obj][is_frame]
    ts = stamp["ts"]
    ten_us = stamp["oflags"] == 1
    if np.any(ts > _I64_MAX) or np.any(ten_us & (ts > _MAX_10US)):
        return None
    t_ns = np.where(ten_us, ts.astype(np.int64) * 10000, ts.astype(np.int64))
    ch = np.zeros(n, np.int64)
    ident = np.zeros(n, np.int64)
    fl = np.zeros(n, np.int64)
    dlc = np.zeros(n, np.int64)
    nbytes = np.zeros(n, np.int64)
    wide = bool(np.any(_IS_WIDE[f_type]))
    data = np.zeros((n, 64 if wide else 8), np.uint8)
    p = f_pos + f_h

    m = (f_type == K.CAN_MESSAGE) | (f_type == K.CAN_MESSAGE2)
    if m.any():
        r = _gather(arr, p[m], _CAN)
        code = r["dlc"].astype(np.int64)
        remote = (r["fl"] & 0x80) != 0
        ch[m], ident[m], dlc[m] = r["ch"].astype(np.int64) - 1, r["id"], code
        fl[m] = np.where(remote, RTR, 0) | np.where(r["fl"] & 1, TX, 0)
        nbytes[m] = np.where(remote, 0, np.minimum(code, 8))
        data[m, :8] = r["data"]
    for t in (K.CAN_FD_MESSAGE, K.CAN_FD_MESSAGE_64, K.CAN_ERROR_EXT, K.CAN_ERROR, K.CAN_FD_ERROR_64):
        m = f_type == t
        if not m.any():
            continue
        avail = f_size[m] - f_h[m]
        if t == K.CAN_FD_MESSAGE:
            r = _gather(arr, p[m], _CAN_FD)
            if np.any(r["valid"] > 64):
                return None
            remote = (r["fl"] & 0x80) != 0
            f = (np.where(r["fdf"] & 1, FD, 0) | np.where(r["fdf"] & 2, BRS, 0) | np.where(r["fdf"] & 4, ESI, 0)
                 | np.where(remote, RTR, 0) | np.where(r["fl"] & 1, TX, 0))
            ch[m], ident[m], fl[m], dlc[m] = r["ch"].astype(np.int64) - 1, r["id"], f, _DLC_LEN[r["dlc"]]
            nbytes[m] = np.where(remote, 0, np.clip(np.minimum(r["valid"], avail - 20), 0, 64))
        elif t == K.CAN_FD_MESSAGE_64:
            r = _gather(arr, p[m], _CAN_FD64)
            if np.any(r["valid"] > 64):
                return None
            g = r["flags"]
            remote = (g & 0x10) != 0
            f = (np.where(g & 0x1000, FD, 0) | np.where(g & 0x2000, BRS, 0) | np.where(g & 0x4000, ESI, 0)
                 | np.where(remote, RTR, 0) | np.where(r["dir"] != 0, TX, 0))
            stop = np.where(r["ext_off"] != 0, r["ext_off"], f_size[m])
            ch[m], ident[m], fl[m], dlc[m] = r["ch"].astype(np.int64) - 1, r["id"], f, _DLC_LEN[r["dlc"]]
            nbytes[m] = np.where(remote, 0, np.clip(np.minimum(r["valid"], stop - f_h[m] - 40), 0, 64))
        elif t == K.CAN_ERROR_EXT:
            r = _gather(arr, p[m], _ERR_EXT)
            code = r["dlc"].astype(np.int64)
            ch[m], ident[m], fl[m], dlc[m] = r["ch"].astype(np.int64) - 1, r["id"], ERR, code
            nbytes[m] = np.minimum(code, 8)
        elif t == K.CAN_ERROR:
            r = _gather(arr, p[m], _ERR)
            ch[m], fl[m] = r["ch"].astype(np.int64) - 1, ERR
        else:
            r = _gather(arr, p[m], _FD_ERR64)
            if np.any(r["valid"] > 64):
                return None
            ch[m], ident[m], fl[m] = r["ch"].astype(np.int64) - 1, r["id"], ERR | FD
            dlc[m] = _DLC_LEN[r["dlc"] & 0xF]
            nbytes[m] = np.clip(np.minimum(r["valid"], avail - 44), 0, 64)
        width = min(data.shape[1], r["data"].shape[1]) if "data" in (r.dtype.names or ()) else 0
        if width:
            data[m, :width] = r["data"][:, :width]
    fl |= np.where(ident & 0x80000000, EXT, 0)
    ident &= 0x1FFFFFFF
    ch = np.where((ch < -1) | (ch > 32767), -1, ch)
    data[np.arange(data.shape[1])[None, :] >= nbytes[:, None]] = 0
    return Decoded(t_ns, ch, ident, fl, dlc, data, tail, type_counts)
