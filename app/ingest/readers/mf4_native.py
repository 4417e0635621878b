"""CAN frames out of MDF 4 bus-logging groups with numpy, without asammdf.

A bus-logging channel group carries a master channel (``Timestamp``, seconds after the
conversion) and one composed channel named after the event type (``CAN_DataFrame``,
``CAN_RemoteFrame``, ``CAN_ErrorFrame``) whose members (``.ID``, ``.IDE``, ``.DLC``,
``.DataLength``, ``.DataBytes``, ``.BusChannel``, ``.Dir``, ``.EDL``, ``.BRS``, ``.ESI``) are
bit fields of the group's records. Layouts read here:

* sorted data groups (record id size 0, one channel group): records are rows of the data
  blocks, read block by block (a DT, a DZ, or a DL/HL list of them) -- memory is one block;
* unsorted data groups (CANedge writes them, often unfinalised): records of several groups
  and variable-length (VLSD) payload records interleaved, told apart by their record id;
* ``.DataBytes`` fixed-width or VLSD (in an SD block or a VLSD channel group).

The field values become the same columns asammdf's ``get(..., raw=True)`` gives and go
through :func:`app.ingest.readers.mf4.frames_from_samples`, so both readers share one set of
frame rules (the tests check the frames equal asammdf's on every MF4 in the shared data).
Anything else raises :class:`~app.ingest.readers.mf4_blocks.Unsupported` with the reason.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numpy as np
import numpy.typing as npt

from app.ingest.readers.mf4_blocks import (
    Bytes,
    Channel,
    ChannelGroup,
    Damaged,
    DataGroup,
    MdfFile,
    Problems,
    Unsupported,
)

GROUP_KINDS = ("CAN_DataFrame", "CAN_RemoteFrame", "CAN_ErrorFrame")


@dataclass
class CanGroup:
    """A bus-logging channel group: its event kind, master and members."""

    kind: str
    dg: DataGroup
    cg: ChannelGroup
    master: Channel
    members: dict[str, Channel]


class _Fields:
    """Columns by name with the ``dtype.names`` / ``[name]`` access of a structured array."""

    def __init__(self, cols: dict[str, npt.NDArray[np.generic]]) -> None:
        self.cols = cols
        self.dtype = SimpleNamespace(names=tuple(cols))

    def __getitem__(self, name: str) -> npt.NDArray[np.generic]:
        return self.cols[name]


def can_groups(mdf: MdfFile) -> list[CanGroup]:
    """Every CAN event group of the file, checked to be readable here."""
    out = []
    for dg in mdf.data_groups:
        for cg in dg.groups:
            comp = next((c for c in cg.channels if c.name in GROUP_KINDS and c.children), None)
            if comp is None:
                continue
            master = next((c for c in cg.channels if c.cn_type in (2, 3) and c.sync_type == 1), None)
            if master is None or master.cn_type != 2 or master.data_type not in (0, 4) or master.bit_offset:
                raise Unsupported(f"{comp.name} group at offset {cg.offset}: time master channel not stored "
                                  "as a plain integer or float")
            if master.data_type == 4 and master.bit_count not in (32, 64):
                raise Unsupported(f"{comp.name} group: {master.bit_count}-bit float time")
            if dg.record_id_size == 0 and len(dg.groups) > 1:
                raise Unsupported("a sorted data group with several channel groups")
            members = {c.name: c for c in comp.children}
            for c in members.values():
                if c.cn_type == 1 and c.name.endswith(".DataBytes"):
                    continue
                if c.cn_type != 0 or c.data_type not in (0, 10) or (c.bit_count > 64 and c.data_type == 0):
                    raise Unsupported(f"channel {c.name}: type {c.cn_type}, data type {c.data_type}")
            out.append(CanGroup(comp.name, dg, cg, master, members))
    return out


def _column(rec: Bytes, offset: int, dtype: str) -> npt.NDArray[Any]:
    """A strided view of one byte-aligned field of every record (no copy)."""
    width = np.dtype(dtype).itemsize
    field = rec[:, offset:offset + width]
    if field.strides[-1] != 1:
        field = np.ascontiguousarray(field)
    return field.view(dtype)[:, 0]


def _uint(rec: Bytes, ch: Channel) -> npt.NDArray[np.unsignedinteger]:
    """An unsigned little-endian bit field of every record."""
    nbytes = (ch.bit_offset + ch.bit_count + 7) // 8
    if ch.byte_offset + nbytes > rec.shape[1]:
        raise Damaged(0, f"channel {ch.name} lies outside its {rec.shape[1]}-byte record")
    if nbytes in (1, 2, 4, 8):
        cols = _column(rec, ch.byte_offset, f"<u{nbytes}")
        if not ch.bit_offset and ch.bit_count == 8 * nbytes:
            return cols  # a whole byte-aligned integer: asammdf's dtype, no copy beyond the column
        val = cols.astype(np.uint64)
    else:
        val = np.zeros(len(rec), np.uint64)
        for k in range(nbytes):
            val |= rec[:, ch.byte_offset + k].astype(np.uint64) << np.uint64(8 * k)
    if ch.bit_offset:
        val >>= np.uint64(ch.bit_offset)
    if ch.bit_count < 64:
        val &= np.uint64((1 << ch.bit_count) - 1)
    return val


def _master(rec: Bytes, ch: Channel) -> npt.NDArray[np.float64]:
    """Time in s: the raw value through the linear conversion, in asammdf's order of operations."""
    if ch.data_type == 4:
        w = ch.bit_count // 8
        t = _column(rec, ch.byte_offset, f"<f{w}").astype(np.float64)
    else:
        t = _uint(rec, ch).astype(np.float64)
    if ch.conversion is not None:
        a, b = ch.conversion
        if (a, b) != (1, 0):
            t = t * a
            if b:
                t += b
    return t


def _vlsd_table(stream: Bytes) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Start offsets and lengths of the ``uint32 length + bytes`` entries of a VLSD stream."""
    starts, lengths = [], []
    raw = stream.tobytes()
    pos, end = 0, len(raw)
    while pos + 4 <= end:
        n = int.from_bytes(raw[pos:pos + 4], "little")
        if pos + 4 + n > end:
            break
        starts.append(pos)
        lengths.append(n)
        pos += 4 + n
    return np.array(starts, np.int64), np.array(lengths, np.int64)


def _payloads(stream: Bytes, offsets: npt.NDArray[np.uint64]) -> tuple[npt.NDArray[np.uint8], npt.NDArray[np.bool_]]:
    """``(n, width)`` zero-padded payload bytes of VLSD entries at ``offsets`` of ``stream``; which were found."""
    starts, lengths = _vlsd_table(stream)
    if not len(starts):
        return np.zeros((len(offsets), 1), np.uint8), np.zeros(len(offsets), bool)
    at = offsets.astype(np.int64)
    idx = np.minimum(np.searchsorted(starts, at), len(starts) - 1)
    found = starts[idx] == at
    length = np.where(found, lengths[idx], 0)
    out = np.zeros((len(offsets), max(int(length.max(initial=0)), 1)), np.uint8)
    k = np.arange(out.shape[1])
    take = k[None, :] < length[:, None]
    src = np.minimum((starts[idx] + 4)[:, None] + k[None, :], len(stream) - 1)
    out[take] = stream[src][take]
    return out, found


def group_columns(group: CanGroup, rec: Bytes, vlsd: Bytes | None,
                  ) -> tuple[_Fields, npt.NDArray[np.float64], npt.NDArray[np.bool_] | None]:
    """The member columns (asammdf's names and values) and the time of records ``rec``.

    The third item marks the records whose VLSD payload was found (None: fixed-width payloads).
    """
    cols: dict[str, npt.NDArray[np.generic]] = {}
    found = None
    for name, ch in group.members.items():
        if name.endswith(".DataBytes") and ch.cn_type == 1:
            cols[name], found = _payloads(vlsd if vlsd is not None else np.empty(0, np.uint8), _uint(rec, ch))
        elif ch.data_type == 10:
            w = ch.bit_count // 8
            if ch.byte_offset + w > rec.shape[1]:
                raise Damaged(0, f"channel {name} lies outside its {rec.shape[1]}-byte record")
            cols[name] = rec[:, ch.byte_offset:ch.byte_offset + w]
        else:
            cols[name] = _uint(rec, ch)
    return _Fields(cols), _master(rec, group.master), found


def _plausible(rows: Bytes, master: Channel) -> int:
    """Length of the prefix of ``rows`` whose time is finite and never steps back."""
    t = _master(rows, master)
    with np.errstate(invalid="ignore", over="ignore"):
        bad = ~np.isfinite(t)
        bad[1:] |= np.diff(t) < 0
    return int(np.argmax(bad)) if bad.any() else len(rows)


def sorted_records(mdf: MdfFile, group: CanGroup, problems: Problems, step: int) -> Iterator[Bytes]:
    """Records of a sorted group in slices of at most ``step`` rows, read block by block."""
    size = group.cg.record_size
    if size <= 0:
        return
    want = None if mdf.unfinalised & 1 else group.cg.cycles
    got = 0
    damaged_any = False
    carry = np.empty(0, np.uint8)
    for leaf in mdf.leaves(group.dg.data_link, problems):
        damaged = bool(problems) and problems[-1][0] == "corrupt_zlib"
        damaged_any = damaged_any or damaged
        buf = np.concatenate([carry, leaf]) if carry.size else leaf
        n = buf.size // size
        if want is not None:
            n = min(n, want - got)
        rows = buf[:n * size].reshape(n, size)
        if damaged:  # zlib detects damage late: keep records while time stays finite and ordered
            n = _plausible(rows, group.master)
            rows, buf = rows[:n], buf[:n * size]
        carry = buf[n * size:] if want is None or got + n < want else np.empty(0, np.uint8)
        for i in range(0, n, step):
            yield rows[i:i + step]
        got += n
    if damaged_any and want is not None and got < want:
        problems.append(("bad_record", group.cg.offset, f"{group.kind}: {want - got} of {want} records lost to "
                         "the damaged data block(s) reported above", 0, want - got))
    elif carry.size or (want is not None and got < want):
        problems.append(("truncated", group.cg.offset, f"{group.kind}: data ends {carry.size} bytes into a record "
                         + (f"after {got} of {want} records" if want is not None else "") + " (truncated)",
                         int(carry.size)))


def unsorted_records(mdf: MdfFile, dg: DataGroup, problems: Problems) -> dict[int, Bytes]:
    """Split an unsorted data group into per-record-id arrays (VLSD groups: their raw stream).

    A record id the group does not declare ends the walk (the rest cannot be framed) and is
    reported with the bytes left.
    """
    raw = mdf.data(dg.data_link, problems)
    data = raw.tobytes()
    rid = dg.record_id_size
    sizes = {cg.record_id: (-1 if cg.vlsd else cg.record_size) for cg in dg.groups}
    where: dict[int, list[int]] = {r: [] for r in sizes}
    vlsd: dict[int, list[bytes]] = {r: [] for r, s in sizes.items() if s < 0}
    pos, end = 0, len(data)
    while pos + rid <= end:
        r = int.from_bytes(data[pos:pos + rid], "little")
        size = sizes.get(r)
        if size is None:
            problems.append(("bad_record", pos, f"unsorted data: unknown record id {r} at data byte {pos}; "
                             f"the last {end - pos} bytes cannot be framed", end - pos))
            pos = end
            break
        body = pos + rid
        if size < 0:
            n = int.from_bytes(data[body:body + 4], "little") if body + 4 <= end else end
            if body + 4 + n > end:
                break
            vlsd[r].append(data[body:body + 4 + n])
            pos = body + 4 + n
            continue
        if body + size > end:
            break
        where[r].append(body)
        pos = body + size
    if pos < end:
        problems.append(("truncated", pos, f"unsorted data ends {end - pos} bytes into a record (truncated)",
                         end - pos))
    out: dict[int, Bytes] = {}
    for r, s in sizes.items():
        if s < 0:
            out[r] = np.frombuffer(b"".join(vlsd[r]), np.uint8)
        else:
            starts = np.array(where[r], np.int64)
            out[r] = raw[starts[:, None] + np.arange(s)[None, :]] if len(starts) else np.empty((0, s), np.uint8)
    return out
