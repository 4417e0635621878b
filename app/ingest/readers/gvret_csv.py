"""SavvyCAN / GVRET CSV logs, both header variants.

::

    Time Stamp,ID,Extended,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8            older SavvyCAN (the Kona EV logs)
    Time Stamp,ID,Extended,Dir,Bus,LEN,D1,D2,D3,D4,D5,D6,D7,D8        newer SavvyCAN / ESP32RET (Rx/Tx)
    303004300,00000450,false,0,3,00,C2,05                             a row carries only LEN data fields

Timestamps are microseconds of the capture device's clock (not an epoch), so
``start_time`` stays unknown and ``t_ns`` is that clock in ns. When the first timestamp is
already a plausible epoch (after 2000; SavvyCAN's "system clock" option), it becomes
``start_time`` (``"epoch_utc"``) and ``t_ns`` counts from it. Rows are kept in logged
order: with several buses the timestamps are not monotonic, and every backwards step is
counted in the report (``time_backwards``). Buses are 0-based already.
"""

from __future__ import annotations

from app.errors import LogFormatError
from app.ingest.frames import FrameFlag
from app.ingest.readers._text import (
    LEN_TO_DLC,
    BadLine,
    LineFrame,
    LineFrameReader,
    decimal_to_ns,
    first_stamp,
    hex_bytes,
    parse_int,
    printable,
)
from app.log_formats import LogFormat

EXT, FD, TX = int(FrameFlag.EXTENDED), int(FrameFlag.FD), int(FrameFlag.TX)
_BOOL = {"true": True, "false": False, "1": True, "0": False}

Frame = tuple[int, int, int, int, int, bytes]


ROW = r"(?i)^\d+(\.\d+)?,(0x)?[0-9A-Fa-f]{1,8},(true|false),((Rx|Tx),)?\d+,\d+(,[0-9A-Fa-f]{1,2})*,?\s*$"
FORMAT = LogFormat(name="gvret_csv", reader="GvretCsvReader", label="SavvyCAN/GVRET CSV", order=50,
                   suffixes=(".csv",), lines=(r"(?i)^\s*Time Stamp,ID,Extended,(Dir,)?Bus,LEN", ROW))


class GvretCsvReader(LineFrameReader):
    """SavvyCAN/GVRET CSV reader (see the module docstring)."""

    fmt = FORMAT.name
    unit = "row"

    def _open(self) -> None:
        # column of: time, id, extended, dir (None: absent), bus, len -- the older variant by default
        self._layout: tuple[int, int, int, int | None, int, int] = (0, 1, 2, None, 3, 4)
        first = self._head.decode("latin-1").split("\n", 1)[0].strip().lstrip("\ufeff")
        if first.lower().startswith("time stamp"):
            names = [c.strip().lower() for c in first.split(",")]
            try:
                self._layout = (names.index("time stamp"), names.index("id"), names.index("extended"),
                                names.index("dir") if "dir" in names else None, names.index("bus"),
                                names.index("len"))
            except ValueError as exc:
                raise LogFormatError(f"{self.name}: GVRET CSV header lacks a column ({exc}): {first[:80]!r}") from None
            self.meta.extra["header"] = first
        elif len(fields := first.split(",")) > 4 and fields[3].strip() in ("Rx", "Tx"):
            self._layout = (0, 1, 2, 3, 4, 5)
        self.meta.extra["time_base"] = "GVRET device clock (microseconds)"
        t = first_stamp(self._head.decode("latin-1").splitlines()[1:1000], self.parse_line)
        if t is not None:
            self._set_origin(t)

    def _set_origin(self, t: int) -> None:
        super()._set_origin(t)
        if self.meta.start_clock == "epoch_utc":
            self.meta.extra["time_base"] = "epoch microseconds (system clock)"

    def parse_line(self, line: str) -> Frame | None:
        """One CSV row as ``(device t_ns, bus, id, flags, len, payload)``; damage raises :class:`BadLine`."""
        s = line.strip()
        if not s or s.lower().startswith("time stamp"):
            return None
        if not printable(s):
            raise BadLine("bad_line", "binary data (non-printable bytes) instead of a CSV row")
        f = s.split(",")
        i_t, i_id, i_ext, i_dir, i_bus, i_len = self._layout
        if len(f) <= i_len:
            raise BadLine("short_data", f"{len(f)} fields, at least {i_len + 1} expected")
        t = decimal_to_ns(f[i_t].strip(), 3)
        id_tok = f[i_id].strip()
        ident = parse_int(id_tok[2:] if id_tok[:2].lower() == "0x" else id_tok, 16, "identifier")
        ext = _BOOL.get(f[i_ext].strip().lower())
        if ext is None:
            raise BadLine("bad_line", f"Extended field {f[i_ext]!r} is not true/false")
        if ident > (0x1FFFFFFF if ext else 0x7FF):
            raise BadLine("bad_line", f"identifier {id_tok} too large for a {'29' if ext else '11'}-bit ID")
        bus = parse_int(f[i_bus].strip(), 10, "bus")
        if bus > 32767:
            raise BadLine("bad_line", f"bus {bus} out of range")
        length = parse_int(f[i_len].strip(), 10, "LEN")
        if length > 64 or (length > 8 and length not in LEN_TO_DLC):
            raise BadLine("bad_line", f"LEN {length} is not a CAN or CAN FD length")
        fl = (EXT if ext else 0) | (FD if length > 8 else 0)
        if i_dir is not None and f[i_dir].strip() == "Tx":
            fl |= TX
        payload = hex_bytes([x.strip() for x in f[i_len + 1:]], length)
        return t, bus, ident, fl, length, payload

    def _frame(self, line: str) -> LineFrame | None:
        return self.parse_line(line)
