"""Which format is this log? Decided by content; the file suffix only breaks ties.

Binary formats have magic bytes (BLF ``LOGG``, MDF ``MDF     `` / ``UnFinMF ``). Text formats
are scored by how many of the first lines have that format's unmistakable shape; a gzip
head is inflated first. Both come from the formats the readers declare, :data:`app.log_formats.LOG_FORMATS`.
CANedge's compressed/encrypted MF4 containers (``Generic File``)
are recognised only to refuse them with a clear message.
"""

from __future__ import annotations

import re
import zlib
from pathlib import PurePath

from app.errors import LogFormatError, UnsupportedFormatError
from app.ingest.readers.described import TextLayout, user_layouts
from app.log_formats import FORMAT_NAMES, LOG_FORMATS, supported_list

FORMATS = FORMAT_NAMES

SUFFIXES = {suffix: f.name for f in LOG_FORMATS for suffix in f.suffixes}
_MAGIC = tuple((magic, f.name) for f in LOG_FORMATS for magic in f.magic)
_LINE_RULES: dict[str, tuple[re.Pattern[str], ...]] = {
    f.name: tuple(re.compile(p) for p in f.lines) for f in LOG_FORMATS if f.lines}


def _inflate_head(head: bytes) -> bytes:
    """As much of a gzip member's start as the given bytes decompress to."""
    d = zlib.decompressobj(16 + zlib.MAX_WBITS)
    try:
        return d.decompress(head, 1 << 20)
    except zlib.error as exc:
        raise LogFormatError(f"gzip data cannot be decompressed: {exc}") from exc


def _suffix_format(name: str | None) -> str | None:
    if not name:
        return None
    suffixes = [s.lower() for s in PurePath(name).suffixes]
    if suffixes and suffixes[-1] == ".gz":
        suffixes.pop()
    return SUFFIXES.get(suffixes[-1]) if suffixes else None


def unsupported(name: str | None, why: str) -> UnsupportedFormatError:
    label = f"{name}: " if name else ""
    return UnsupportedFormatError(f"{label}{why}; supported formats: {supported_list()}; any of them "
                                  "gzip-compressed")


def _head_lines(head: bytes) -> list[str]:
    lines = head.decode("latin-1").splitlines()[:200]
    if len(head) >= 65536 and len(lines) > 1:
        lines = lines[:-1]  # the last line may be cut
    return lines


def _text_head(head: bytes) -> bytes | None:
    """The bytes to look at for text lines: ``head`` itself, inflated for gzip; None for binary formats."""
    if head[:2] == b"\x1f\x8b":
        try:
            return _inflate_head(head)
        except LogFormatError:
            return None
    if head[:4] == b"LOGG" or head[:8] in (b"MDF     ", b"UnFinMF ") or head[:12] == b"Generic File":
        return None
    return head


def described_match(head: bytes, layouts: list[TextLayout]) -> TextLayout | None:
    """The first user description whose shape at least half of the log's first lines have (and one at least)."""
    text = _text_head(head) if layouts and head else None
    if not text:
        return None
    lines = [line for line in _head_lines(text) if line.strip()]
    for layout in layouts:
        body = lines[layout.skip_lines:]
        hits = sum(1 for line in body if layout.matches(line))
        if hits and 2 * hits >= len(body):
            return layout
    return None


def sniff_source(head: bytes, name: str | None = None) -> tuple[str, TextLayout | None]:
    """The format of a log, user descriptions first (:func:`described_match`), then :func:`sniff_format`;
    with the description when one matched."""
    layout = described_match(head, user_layouts())
    if layout is not None:
        return "described", layout
    return sniff_format(head, name), None


def sniff_format(head: bytes, name: str | None = None) -> str:
    """The format of a log from its first bytes (content first; ``name``'s suffix breaks ties).

    Parameters
    ----------
    head : bytes
        The first bytes of the file (64 kB is plenty; fewer work for most formats).
    name : str, optional
        File name; its suffix (``.blf``, ``.asc``, ``.asc.gz`` ...) is used only when the
        content matches several text formats equally well.

    Returns
    -------
    str
        One of ``FORMATS``.

    Raises
    ------
    LogFormatError
        ``head`` is empty, or is gzip data that cannot be inflated.
    UnsupportedFormatError
        Nothing recognisable; the message lists the supported formats.
    """
    if not head:
        raise LogFormatError(f"{name + ': ' if name else ''}empty log")
    if head[:2] == b"\x1f\x8b":
        inner = _inflate_head(head)
        if not inner:
            raise LogFormatError(f"{name + ': ' if name else ''}empty log (gzip member decompresses to nothing)")
        return sniff_format(inner, name[:-3] if name and name.lower().endswith(".gz") else name)
    for magic, fmt in _MAGIC:
        if head.startswith(magic):
            return fmt
    if head[:12] == b"Generic File":
        raise unsupported(name, "this is a CANedge compressed or encrypted MF4 container (MFC/MFE), which needs "
                          "the vendor's decompression/decryption first")
    lines = _head_lines(head)
    scores = {fmt: sum(1 for line in lines if any(r.match(line) for r in rules))
              for fmt, rules in _LINE_RULES.items()}
    best = max(scores.values())
    if best == 0:
        if b"\0" in head[:4096]:
            raise unsupported(name, "binary content with no known signature")
        raise unsupported(name, "no line has the shape of a supported text log")
    leaders = [fmt for fmt, s in scores.items() if s == best]
    suffix = _suffix_format(name)
    if len(leaders) > 1 and suffix in leaders:
        return suffix
    return leaders[0]
