"""Raw signal bits out of payload byte arrays, vectorized over frames.

Bit numbering follows the DBC convention cantools uses. Little-endian (Intel) signals give the
least significant bit ``start``; bit ``k`` is bit ``k % 8`` of byte ``k // 8``. Big-endian
(Motorola) signals give their most significant bit in the same "sawtooth" numbering; counting
in network order instead (bit 0 = MSB of byte 0) the signal occupies ``length`` consecutive
bits::

    byte        |        0        |        1        |
    sawtooth    | 7 6 5 4 3 2 1 0 | 15 14 ...     8 |
    network     | 0 1 2 3 4 5 6 7 | 8  9  ...    15 |

A signal is read from a 64-bit window of 8 payload bytes (little-endian word for Intel,
big-endian word for Motorola) starting at its first byte; a signal of more than 56 bits that
does not start on a byte boundary spills into a ninth byte, which is merged in separately.
Payloads are zero padded to a multiple of 8 bytes so every window exists.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

U64 = npt.NDArray[np.uint64]


@dataclass(frozen=True, slots=True)
class SignalLayout:
    """Where a signal's bits are and how to interpret them.

    ``first_bit`` is the LSB (little-endian) or the network-order MSB (big-endian);
    ``end_bit`` is one past the last payload bit the signal uses in the order cantools checks
    truncated payloads against (``8 * received_bytes``).
    """

    first_bit: int
    length: int
    big_endian: bool
    signed: bool
    float_bits: int  # 0: integer; 16/32/64: IEEE float of that width

    @staticmethod
    def of(start: int, length: int, big_endian: bool, signed: bool, float_bits: int = 0) -> SignalLayout:
        first = 8 * (start // 8) + (7 - start % 8) if big_endian else start
        return SignalLayout(first, length, big_endian, signed, float_bits)

    @property
    def end_bit(self) -> int:
        return self.first_bit + self.length


def _word(payload: npt.NDArray[np.uint8], byte: int, big_endian: bool, cache: dict[tuple[int, bool], U64]) -> U64:
    key = (byte, big_endian)
    got = cache.get(key)
    if got is None:
        block = payload if payload.shape[1] == 8 and payload.flags.c_contiguous else \
            np.ascontiguousarray(payload[:, byte:byte + 8])
        word = block.view(">u8" if big_endian else "<u8").reshape(-1)
        got = word if word.dtype == np.uint64 else word.astype(np.uint64)  # native order: no copy
        cache[key] = got
    return got


def extract_raw(payload: npt.NDArray[np.uint8], layout: SignalLayout,
                cache: dict[tuple[int, bool], U64] | None = None) -> npt.NDArray[np.generic]:
    """Raw values of one signal for every row of ``payload``.

    Parameters
    ----------
    payload
        ``(n, width)`` uint8, ``width`` a multiple of 8 covering the signal.
    layout
        The signal's bit position, length and type.
    cache
        64-bit windows already built for this payload (reused across signals).

    Returns
    -------
    ndarray
        ``(n,)`` uint64 (unsigned), int64 (signed) or float64 (float signals).
    """
    cache = {} if cache is None else cache
    width = payload.shape[1]
    length = layout.length
    first_byte = layout.first_bit // 8
    base = min(first_byte, width - 8)
    rel = layout.first_bit - 8 * base
    word = _word(payload, base, layout.big_endian, cache)
    spill = rel + length > 64  # only when base == first_byte, so byte base + 8 < width exists
    if layout.big_endian:
        if spill:
            extra = payload[:, base + 8].astype(np.uint64) >> np.uint64(8 - rel)
            value = ((word << np.uint64(rel)) | extra) >> np.uint64(64 - length)
        else:
            value = word >> np.uint64(64 - rel - length)
    else:
        value = word >> np.uint64(rel)
        if spill:
            value = value | (payload[:, base + 8].astype(np.uint64) << np.uint64(64 - rel))
    if length < 64:
        value = value & np.uint64((1 << length) - 1)
    if layout.float_bits:
        ftype = {16: np.float16, 32: np.float32, 64: np.float64}[layout.float_bits]
        itype = {16: np.uint16, 32: np.uint32, 64: np.uint64}[layout.float_bits]
        with np.errstate(invalid="ignore"):  # signalling NaN payloads convert quietly, as in Python
            return value.astype(itype).view(ftype).astype(np.float64)
    if not layout.signed:
        return value
    if length == 64:
        return value.view(np.int64)
    sign = np.int64(1 << (length - 1))
    return (value.astype(np.int64) ^ sign) - sign
