"""ASAM MDF 4.1 blocks, as far as bus logging needs them, read straight from a memory map.

Every block starts with a 24-byte header (``##XX`` id, reserved, uint64 length, uint64 link
count), then its links (uint64 file offsets, 0 = none), then its data. What is read here::

    ID   (offset 0, 64 bytes)  "MDF     " or "UnFinMF ", version (uint16 at 28), unfinalised flags (60)
    ##HD header      links: first DG ...;   data: start time (uint64 ns UTC)
    ##DG data group  links: next DG, first CG, data;   data: record id size (0, 1, 2, 4, 8 bytes)
    ##CG channel grp links: next CG, first CN, acquisition name;  data: record id, cycles, flags, bytes
    ##CN channel     links: next CN, composition, name, source, conversion, data;  data: types, offsets
    ##TX text        data: UTF-8, NUL-terminated
    ##CC conversion  only "none" and linear (phys = a * raw + b) are used here
    ##DT / ##SD      raw records / variable-length signal data
    ##DZ             deflate (zip type 0) or transposed + deflate (1) of a DT/SD
    ##DL / ##HL      lists of data blocks (in order); HL heads a DL chain

:class:`Unsupported` marks a layout this reader does not handle (the caller falls back to
asammdf and says why); :class:`Damaged` marks a block that cannot be right (bad id, length
past the end of the file, a loop in a chain) and names its offset.
"""

from __future__ import annotations

import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from app.ingest.readers.blf_containers import inflate_prefix

Bytes = npt.NDArray[np.uint8]
# (issue kind, offset, message, bytes lost[, frames lost])
Problems = list[tuple[str, int, str, int] | tuple[str, int, str, int, int]]
_HEADER = 24
_MAX_CHAIN = 1 << 20  # blocks in one chain: more means a loop or garbage


class Unsupported(Exception):
    """A valid MDF layout the native reader does not read (the reason is the message)."""


class Damaged(Exception):
    """A block that cannot be valid; ``offset`` is where it was expected."""

    def __init__(self, offset: int, message: str) -> None:
        super().__init__(message)
        self.offset = offset


@dataclass
class Channel:
    """One ##CN block: where its value sits in a record and how to read it."""

    name: str
    cn_type: int  # 0 fixed, 1 VLSD, 2 master, 3 virtual master ...
    sync_type: int
    data_type: int  # 0 uint LE, 1 uint BE, 2 int LE, 4 float LE, 10 byte array ...
    bit_offset: int
    byte_offset: int
    bit_count: int
    conversion: tuple[float, float] | None  # linear (a, b); None: no conversion
    data_link: int
    children: list[Channel] = field(default_factory=list)


@dataclass
class ChannelGroup:
    """One ##CG block with its channels and the data group it belongs to."""

    name: str
    record_id: int
    cycles: int
    flags: int
    data_bytes: int
    inval_bytes: int
    channels: list[Channel]
    offset: int

    @property
    def vlsd(self) -> bool:
        """A VLSD group: records are uint32 length + bytes (bit 0 of cg_flags)."""
        return bool(self.flags & 1)

    @property
    def record_size(self) -> int:
        return self.data_bytes + self.inval_bytes


@dataclass
class DataGroup:
    record_id_size: int
    data_link: int
    groups: list[ChannelGroup]


class MdfFile:
    """The block tree of an MDF 4 file held in ``buf`` (a memory map or array of the whole file)."""

    def __init__(self, buf: Bytes) -> None:
        self.buf = buf
        self.size = int(buf.size)
        if self.size < 64 + _HEADER:
            raise Damaged(0, f"{self.size} bytes: shorter than the MDF identification and header blocks")
        magic = bytes(buf[:8])
        if magic not in (b"MDF     ", b"UnFinMF "):
            raise Damaged(0, f"identification block starts with {magic!r}, not 'MDF     '")
        self.version = int(buf[28:30].view("<u2")[0])
        if not 400 <= self.version < 500:
            raise Unsupported(f"MDF version {self.version / 100:g} (the native reader reads MDF 4)")
        self.unfinalised = int(buf[60:62].view("<u2")[0]) if magic == b"UnFinMF " else 0
        _, hd_links, hd_data = self.block(64, b"HD")
        self.start_ns = int(self.u64(hd_data))
        self.data_groups = [self._data_group(off) for off in self.chain(hd_links[0], 0, b"DG")]

    # -- primitives --------------------------------------------------------------------------
    def u64(self, at: int) -> int:
        return int(self.buf[at:at + 8].view("<u8")[0])

    def block(self, off: int, kind: bytes | None = None) -> tuple[bytes, list[int], int]:
        """``(id, links, data offset)`` of the block at ``off``; checks id, kind and bounds."""
        if off < 64 or off + _HEADER > self.size:
            raise Damaged(off, f"link to offset {off} points outside the file ({self.size} bytes)")
        head = bytes(self.buf[off:off + 4])
        if head[:2] != b"##" or (kind is not None and head[2:] != kind):
            raise Damaged(off, f"expected a ##{(kind or b'??').decode()} block at offset {off}, found {head!r}")
        length, nlinks = self.u64(off + 8), self.u64(off + 16)
        if length < _HEADER + 8 * nlinks or (off + length > self.size and head != b"##DT"):
            raise Damaged(off, f"{head.decode('latin-1')} block at offset {off} declares {length} bytes and "
                               f"{nlinks} links: past the end of the file or inconsistent")
        links = self.buf[off + _HEADER:off + _HEADER + 8 * nlinks].view("<u8").tolist()
        return head[2:], links, off + _HEADER + 8 * nlinks

    def length(self, off: int) -> int:
        return self.u64(off + 8)

    def chain(self, first: int, link: int, kind: bytes) -> list[int]:
        """Offsets of a linked list of ``kind`` blocks (``link``: index of the "next" link)."""
        out: list[int] = []
        seen: set[int] = set()
        off = first
        while off:
            if off in seen or len(out) > _MAX_CHAIN:
                raise Damaged(off, f"the chain of ##{kind.decode()} blocks loops back to offset {off}")
            seen.add(off)
            out.append(off)
            off = self.block(off, kind)[1][link]
        return out

    def text(self, off: int) -> str:
        if not off:
            return ""
        kind, _, data = self.block(off)
        end = off + self.length(off)
        raw = bytes(self.buf[data:end])
        return raw.split(b"\0", 1)[0].decode("utf-8", "replace") if kind in (b"TX", b"MD") else ""

    # -- tree ----------------------------------------------------------------------------------
    def _data_group(self, off: int) -> DataGroup:
        _, links, data = self.block(off, b"DG")
        rid = int(self.buf[data])
        if rid not in (0, 1, 2, 4, 8):
            raise Damaged(off, f"data group at offset {off}: record id size {rid}")
        groups = [self._channel_group(cg) for cg in self.chain(links[1], 0, b"CG")]
        return DataGroup(rid, links[2], groups)

    def _channel_group(self, off: int) -> ChannelGroup:
        _, links, data = self.block(off, b"CG")
        rec_id, cycles = self.u64(data), self.u64(data + 8)
        flags = int(self.buf[data + 16:data + 18].view("<u2")[0])
        nbytes, inval = (int(v) for v in self.buf[data + 24:data + 32].view("<u4"))
        channels = [self._channel(cn, 0) for cn in self.chain(links[1], 0, b"CN")]
        return ChannelGroup(self.text(links[2]), rec_id, cycles, flags, nbytes, inval, channels, off)

    def _channel(self, off: int, depth: int) -> Channel:
        if depth > 4:
            raise Damaged(off, f"channel compositions nested deeper than 4 at offset {off}")
        _, links, data = self.block(off, b"CN")
        cn_type, sync, dtype, bit_off = (int(v) for v in self.buf[data:data + 4])
        byte_off, bit_count = (int(v) for v in self.buf[data + 4:data + 12].view("<u4"))
        ch = Channel(self.text(links[2]), cn_type, sync, dtype, bit_off, byte_off, bit_count,
                     self._conversion(links[4]), links[5])
        if links[1]:
            kind = bytes(self.buf[links[1] + 2:links[1] + 4])
            if kind != b"CN":
                raise Unsupported(f"channel {ch.name}: a ##{kind.decode('latin-1')} composition")
            ch.children = [self._channel(c, depth + 1) for c in self.chain(links[1], 0, b"CN")]
        return ch

    def _conversion(self, off: int) -> tuple[float, float] | None:
        if not off:
            return None
        _, _, data = self.block(off, b"CC")
        cc_type = int(self.buf[data])
        if cc_type == 0:
            return None
        nvals = int(self.buf[data + 6:data + 8].view("<u2")[0])
        if cc_type != 1 or nvals < 2:
            raise Unsupported(f"conversion type {cc_type} at offset {off} (only linear is read natively)")
        b, a = (float(v) for v in self.buf[data + 24:data + 40].view("<f8"))
        return a, b

    # -- data ----------------------------------------------------------------------------------
    def data(self, off: int, problems: Problems) -> Bytes:
        """The bytes of a DT/SD/DZ block or a DL/HL list, concatenated; damage goes to ``problems``.

        ``problems`` gets ``(kind, offset, message, bytes lost)``; what could be read is returned.
        """
        parts = list(self.leaves(off, problems))
        if len(parts) == 1:
            return parts[0]
        return np.concatenate(parts) if parts else np.empty(0, np.uint8)

    def leaves(self, off: int, problems: Problems) -> Iterator[Bytes]:
        """The data blocks under ``off`` one at a time, in order (memory: one block)."""
        if not off:
            return
        kind, links, _ = self.block(off)
        if kind == b"HL":
            yield from self.leaves(links[0], problems)
        elif kind == b"DL":
            for dl in self.chain(off, 0, b"DL"):
                for leaf in self._list_members(dl):
                    if leaf:
                        yield self._leaf(leaf, problems)
        else:
            yield self._leaf(off, problems)

    def _list_members(self, off: int) -> list[int]:
        _, links, data = self.block(off, b"DL")
        count = int(self.buf[data + 4:data + 8].view("<u4")[0])
        if count > len(links) - 1:
            raise Damaged(off, f"data list at offset {off} names {count} blocks but links {len(links) - 1}")
        return links[1:1 + count]

    def _leaf(self, off: int, problems: Problems) -> Bytes:
        kind, _, data = self.block(off)
        end = off + self.length(off)
        if kind in (b"DT", b"SD", b"RD"):
            if self.unfinalised & 4 and kind == b"DT" and not self._after(off):
                end = self.size  # unfinalised: the last DT block grows to the end of the file
            elif end > self.size:
                problems.append(("truncated", off, f"##{kind.decode()} block at offset {off} ends "
                                 f"{end - self.size} bytes past the end of the file (truncated)", end - self.size))
                end = self.size
            return self.buf[data:end]
        if kind == b"DZ":
            return self._inflate(off, data, end, problems)
        raise Damaged(off, f"expected a data block at offset {off}, found ##{kind.decode('latin-1')}")

    def _after(self, off: int) -> bool:
        """Any block of the tree beyond ``off`` (then a DT cannot run to the end of the file)."""
        return any(dg.data_link > off or any(cg.offset > off for cg in dg.groups) for dg in self.data_groups)

    def _inflate(self, off: int, data: int, end: int, problems: Problems) -> Bytes:
        zip_type = int(self.buf[data + 2])
        columns = int(self.buf[data + 4:data + 8].view("<u4")[0])
        org_len, zip_len = self.u64(data + 8), self.u64(data + 16)
        if zip_type not in (0, 1):
            raise Unsupported(f"DZ block at offset {off}: zip type {zip_type}")
        packed: Any = self.buf[data + 24:min(data + 24 + zip_len, end)]
        inflater = zlib.decompressobj()
        try:
            raw = inflater.decompress(packed.tobytes())
            if not inflater.eof:
                raise zlib.error("stream ends early")
        except zlib.error as exc:  # keep what inflated before the damage
            # a checksum-only fault inflated to bytes wrong somewhere unknown: nothing is kept (as for BLF)
            raw = b"" if "incorrect data check" in str(exc) or zip_type == 1 else inflate_prefix(packed.tobytes())
            raw = raw[:org_len]
            problems.append(("corrupt_zlib", off, f"DZ block at offset {off}: deflate stream damaged ({exc}); "
                             f"{len(raw)} of {org_len} bytes inflate before the damage", org_len - len(raw)))
            return np.frombuffer(raw, np.uint8)
        out = np.frombuffer(raw, np.uint8)
        if len(out) != org_len:
            problems.append(("corrupt_zlib", off, f"DZ block at offset {off}: inflates to {len(out)} bytes, "
                             f"declares {org_len}", abs(org_len - len(out))))
        if zip_type == 1 and columns:
            rows = len(out) // columns
            body = out[:rows * columns].reshape(columns, rows).T.ravel()
            out = np.concatenate([body, out[rows * columns:]])
        return out

