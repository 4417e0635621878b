"""Load CAN databases (DBC, KCD, SYM, ARXML) through cantools, repairing common DBC defects.

Production DBCs are often rejected by strict parsers. In tolerant mode the DBC text is
repaired before cantools parses it, and every repair is reported with the line number it
concerns (1-based, in the original file):

==================  ===========================================================================
kind                repair
==================  ===========================================================================
``missing_bs``      no ``BS_:`` section: an empty one is inserted
``missing_bu``      no ``BU_:`` node list: an empty one is inserted (before the first ``BO_``)
``unused_val``      ``VAL_`` for a message ID or signal the file does not define, or for a signal of
                    CANdb++'s pseudo-message ``VECTOR__INDEPENDENT_SIG_MSG`` (which cantools
                    discards): statement dropped
``unused_comment``  ``CM_`` for that pseudo-message or one of its signals: statement dropped
``signal_outside``  a signal does not fit in its message's length: the ``SG_`` line is dropped
``signal_overlap``  two signals share bits: the second one cantools names is dropped
==================  ===========================================================================

Whatever cantools logs while loading is reported in ``LoadedDatabase.notes`` (the same
:class:`Repair` records, though nothing was changed) instead of reaching stderr:
``duplicate_id`` (two messages share a frame ID; the later one decodes, as in cantools),
``duplicate_name`` and ``database_note`` (any other warning). An empty file, or a DBC without messages that would
need repairs to load, is refused (``empty_database``): nothing is invented for it.

Everything else (syntax errors, bad frame IDs, KCD/SYM/ARXML problems) raises
:class:`~app.errors.DatabaseError` naming the file, the line when known, and the reason.
Strict mode (``tolerant=False``) applies no repairs and passes ``strict=True`` to cantools.

Loading is bounded before and during the work: a DBC with a message of more than
:data:`MAX_SIGNALS_PER_MESSAGE` signals is refused before cantools sees it, and tolerant loading
re-parses the file once per repair for at most :data:`REPAIR_CPU_S` seconds of CPU (a file built
from overlapping signals would otherwise need hundreds of parses); both refusals are
``database_too_complex`` and name the limit.
"""

from __future__ import annotations

import logging
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

import cantools
from cantools.database.can import Database as CanDatabase

from app.errors import DatabaseError

FORMATS = {".dbc": "dbc", ".kcd": "kcd", ".sym": "sym", ".arxml": "arxml", ".xml": "arxml"}
_MAX_REPAIR_ROUNDS = 500  # each round fixes one cantools complaint; bounded so a bad file cannot loop
MAX_SIGNALS_PER_MESSAGE = 1024  # a 64-byte CAN FD frame holds 512 one-bit signals; real files stay far below
REPAIR_CPU_S = 8.0  # CPU seconds tolerant loading may spend re-parsing a DBC to repair it: Model3CAN.dbc needs 7
# parses, 3 s of CPU on a quiet machine and over 5 s with the 2 cores loaded by other work

_RE_BO = re.compile(r"^\s*BO_\s+(\d+)\s+(\w+)\s*:")
_RE_SG = re.compile(r"^\s*SG_\s+(\w+)\s*(?:M|m\d+M?)?\s*:")
_RE_VAL = re.compile(r"^\s*VAL_\s+(\d+)\s+(\w+)\b")
_RE_CM = re.compile(r"^\s*CM_\s+(BO_|SG_)\s+(\d+)\s*(\w*)")
_RE_CM_END = re.compile(r'^\s*CM_[^"]*"(?:[^"\\]|\\.)*"\s*;')  # a whole comment statement, quotes balanced
# CANdb++ puts signals that no message carries into this pseudo-message (ID 0xC0000000, or
# 0x80000000 in older exports); cantools discards it, so its VAL_ and CM_ lines dangle.
PSEUDO_MESSAGE = "VECTOR__INDEPENDENT_SIG_MSG"
_RE_NOT_FIT = re.compile(r"The signal (\w+) does not fit in message (\w+)\.")
_RE_OVERLAP = re.compile(r"The signals (\w+) and (\w+) are overlapping in message (\w+)\.")
_RE_SYNTAX_LINE = re.compile(r"line (\d+)")
_RE_TOP = re.compile(r"^(BO_|BU_|BS_|CM_|BA_|VAL_|SIG_|EV_|NS_|VERSION)\b")  # starts a new statement


@dataclass(frozen=True, slots=True)
class Repair:
    """One change tolerant loading made: its kind, the 1-based line in the original file, and why."""

    kind: str
    line: int | None
    message: str


@dataclass(slots=True)
class LoadedDatabase:
    """A cantools database plus where it came from and what had to be repaired to load it."""

    db: CanDatabase
    source: Path
    format: str
    repairs: list[Repair] = field(default_factory=list)
    encoding: str = "utf-8"
    notes: list[Repair] = field(default_factory=list)  # what cantools warned about while loading (no change made)

    @property
    def name(self) -> str:
        return self.source.name


def detect_format(path: Path, head: bytes) -> str:
    """Database format from the suffix, or from the first bytes when the suffix says nothing."""
    fmt = FORMATS.get(path.suffix.lower())
    if fmt is not None:
        return fmt
    text = head.decode("latin-1")
    if "<AUTOSAR" in text or "autosar.org" in text:
        return "arxml"
    if "<NetworkDefinition" in text:
        return "kcd"
    if "FormatVersion=" in text:
        return "sym"
    if re.search(r"^\s*(VERSION|NS_|BO_|BU_)\b", text, re.MULTILINE):
        return "dbc"
    raise DatabaseError(f"{path}: not a DBC, KCD, SYM or ARXML database (unknown suffix and content)")


def load_database(path: str | Path, *, tolerant: bool = True) -> LoadedDatabase:
    """Load a CAN database, repairing common DBC defects when ``tolerant``.

    Parameters
    ----------
    path
        DBC, KCD, SYM or ARXML file; the format comes from the suffix, else from the content.
    tolerant
        Repair the defects listed in the module docstring and report them in
        ``LoadedDatabase.repairs``. ``False`` loads exactly as cantools does with ``strict=True``.

    Raises
    ------
    DatabaseError
        File missing or unreadable, unsupported format, or a defect that cannot be repaired
        (the message names file, line when known, and reason).
    """
    src = Path(path)
    try:
        raw = src.read_bytes()
    except OSError as exc:
        raise DatabaseError(f"{src}: cannot read database file ({exc.strerror or exc})") from exc
    fmt = detect_format(src, raw[:4096])
    if fmt == "dbc":
        return _load_dbc(src, raw, tolerant)
    try:
        with _CantoolsNotes() as notes:
            db = cantools.database.load_file(str(src), database_format=fmt, strict=True)
    except Exception as exc:  # cantools raises several unrelated types; wrap all at our boundary
        raise DatabaseError(f"{src}: cannot load {fmt.upper()} database: {_reason(exc)}") from exc
    if not isinstance(db, CanDatabase):
        raise DatabaseError(f"{src}: is a diagnostics database, not a CAN database")
    return LoadedDatabase(db, src, fmt, notes=notes.notes())


class _CantoolsNotes(logging.Handler):
    """Collects what cantools logs while loading (it would otherwise reach stderr as raw text)."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        self.records.append(record)

    def __enter__(self) -> _CantoolsNotes:
        log = logging.getLogger("cantools")
        self._propagate = log.propagate
        log.addHandler(self)
        log.propagate = False
        return self

    def __exit__(self, *exc: object) -> None:
        log = logging.getLogger("cantools")
        log.removeHandler(self)
        log.propagate = self._propagate

    def notes(self) -> list[Repair]:
        """Duplicate frame IDs as ``duplicate_id`` notes (cantools keeps the later message); other warnings as is."""
        out: list[Repair] = []
        names: list[tuple[str, str]] = []
        for r in self.records:
            msg, args = r.getMessage(), r.args
            if "name to message" in msg and isinstance(args, tuple) and len(args) == 2:
                names.append((str(args[0]), str(args[1])))
            elif "frame id to message" in msg and isinstance(args, tuple) and len(args) == 3:
                old, new, ident = args
                names = [n for n in names if n != (str(old), str(new))]  # the same pair: said here
                out.append(Repair("duplicate_id", None, f"messages {old} and {new} have the same frame ID "
                                  f"0x{int(str(ident)) & 0x1FFFFFFF:X}; its frames decode as {new} (the later one, "
                                  "as in cantools)"))
            else:
                out.append(Repair("database_note", None, " ".join(msg.split())))
        out += [Repair("duplicate_name", None, f"two messages are named {new}; looking it up by name finds the "
                       "later one (as in cantools)") for _old, new in names]
        return out


def _reason(exc: BaseException) -> str:
    text = str(exc).strip() or type(exc).__name__
    return " ".join(text.split())


def _decode_text(raw: bytes) -> tuple[str, str]:
    """UTF-8 when valid, else cp1252 (the encoding Vector tools write and cantools assumes)."""
    if raw.startswith(b"\xef\xbb\xbf"):
        raw = raw[3:]
    try:
        return raw.decode("utf-8"), "utf-8"
    except UnicodeDecodeError:
        pass
    # cp1252 leaves five bytes undefined; latin-1 maps every byte, so decoding never fails here.
    try:
        return raw.decode("cp1252"), "cp1252"
    except UnicodeDecodeError:
        return raw.decode("latin-1"), "latin-1"


class _DbcText:
    """DBC lines with their original line numbers, so repairs can be reported against the file."""

    def __init__(self, text: str) -> None:
        self.lines: list[str] = text.splitlines()
        self.origin: list[int | None] = list(range(1, len(self.lines) + 1))

    def text(self) -> str:
        return "\n".join(self.lines) + "\n"

    def original_line(self, current_line: int) -> int | None:
        """Original 1-based line number of a 1-based line of the repaired text."""
        if 1 <= current_line <= len(self.origin):
            return self.origin[current_line - 1]
        return None

    def drop(self, index: int, *, statement: bool = False) -> None:
        """Blank a line (or, for ``statement``, the lines up to its closing ';'), keeping numbering."""
        i = index
        while i < len(self.lines):
            done = not statement or ";" in self.lines[i]
            self.lines[i] = ""
            i += 1
            if done or (i < len(self.lines) and _RE_TOP.match(self.lines[i])):
                break

    def drop_comment(self, index: int) -> None:
        """Blank a ``CM_`` statement, whose quoted text may span lines and contain ';'."""
        end = index
        while end + 1 < len(self.lines) and not _RE_CM_END.match("\n".join(self.lines[index:end + 1])):
            if _RE_TOP.match(self.lines[end + 1]):
                break  # an unclosed quote: stop at the next statement
            end += 1
        for i in range(index, min(end + 1, len(self.lines))):
            self.lines[i] = ""

    def insert(self, index: int, line: str) -> None:
        self.lines.insert(index, line)
        self.origin.insert(index, None)

    def messages(self) -> dict[int, tuple[str, int, dict[str, int]]]:
        """frame_id (as written, with the extended bit) -> (name, line index, {signal: line index})."""
        found: dict[int, tuple[str, int, dict[str, int]]] = {}
        current: dict[str, int] | None = None
        for i, line in enumerate(self.lines):
            m = _RE_BO.match(line)
            if m:
                current = {}
                found[int(m.group(1))] = (m.group(2), i, current)
                continue
            s = _RE_SG.match(line)
            if s and current is not None:
                current[s.group(1)] = i
            elif line.strip() and not line.startswith((" ", "\t")):
                current = None
        return found

    def find_signal(self, message: str, signal: str) -> int | None:
        for name, _, signals in self.messages().values():
            if name == message and signal in signals:
                return signals[signal]
        return None


def _insert_missing_sections(doc: _DbcText, repairs: list[Repair]) -> bool:
    """Insert empty ``BS_:``/``BU_:`` statements where they belong; False when both exist."""
    has_bs = any(re.match(r"^\s*BS_\s*:", ln) for ln in doc.lines)
    has_bu = any(re.match(r"^\s*BU_\s*:", ln) for ln in doc.lines)
    if has_bs and has_bu:
        return False
    # Insert after the NS_ block: the first top-level statement that is not VERSION/NS_ (or its
    # indented symbol list), else at the end.
    at = len(doc.lines)
    in_ns = False
    for i, line in enumerate(doc.lines):
        stripped = line.strip()
        if not stripped:
            continue
        if stripped.startswith("NS_"):
            in_ns = True
            continue
        if in_ns and line[:1] in (" ", "\t"):
            continue
        if stripped.startswith("VERSION"):
            continue
        if stripped.startswith(("BS_", "BU_")):
            at = i + 1 if stripped.startswith("BS_") and not has_bu else i
            break
        at = i
        break
    where = doc.original_line(at + 1) if at < len(doc.lines) else len(doc.lines)
    if not has_bu:
        doc.insert(at, "BU_:")
        repairs.append(Repair("missing_bu", where, "no 'BU_:' node list; inserted an empty one"))
    if not has_bs:
        doc.insert(at, "BS_:")
        repairs.append(Repair("missing_bs", where, "no 'BS_:' section; inserted an empty one"))
    return True


def _drop_unused_vals(doc: _DbcText, repairs: list[Repair]) -> None:
    """Drop ``VAL_`` (and, for the CANdb++ pseudo-message, ``CM_``) statements cantools would reject."""
    msgs = doc.messages()
    pseudo = {fid for fid, (name, _, _) in msgs.items() if name == PSEUDO_MESSAGE}
    for i, line in enumerate(doc.lines):
        c = _RE_CM.match(line)
        if c and int(c.group(2)) in pseudo:
            what = f"signal {c.group(3)}" if c.group(1) == "SG_" else "the message"
            repairs.append(Repair("unused_comment", doc.origin[i],
                                  f"comment on {what} of {PSEUDO_MESSAGE} (ID {c.group(2)}), a CANdb++ "
                                  "pseudo-message for signals no message carries, which is not loaded; dropped"))
            doc.drop_comment(i)
            continue
        m = _RE_VAL.match(line)
        if not m:
            continue
        frame_id, sig = int(m.group(1)), m.group(2)
        if frame_id not in msgs:
            why = f"VAL_ for signal {sig} of message ID {frame_id} which the file does not define; dropped"
        elif frame_id in pseudo:
            why = (f"VAL_ for signal {sig} of {PSEUDO_MESSAGE} (ID {frame_id}), a CANdb++ pseudo-message for "
                   "signals no message carries, which is not loaded; dropped")
        elif sig not in msgs[frame_id][2]:
            why = f"VAL_ for signal {sig} which message {msgs[frame_id][0]} (ID {frame_id}) does not have; dropped"
        else:
            continue
        repairs.append(Repair("unused_val", doc.origin[i], why))
        doc.drop(i, statement=True)


def _load_dbc(src: Path, raw: bytes, tolerant: bool) -> LoadedDatabase:
    repairs: list[Repair] = []
    text, encoding = _decode_text(raw)
    if not text.strip():
        raise DatabaseError(f"{src}: the database file is empty", code="empty_database")
    doc = _DbcText(text)
    _check_layout(src, doc)
    if tolerant:
        _drop_unused_vals(doc, repairs)
    sections_checked = False
    started = time.thread_time()
    for _ in range(_MAX_REPAIR_ROUNDS):
        if repairs and time.thread_time() - started > REPAIR_CPU_S:
            raise DatabaseError(f"{src}: still not loadable after {len(repairs)} repairs and {REPAIR_CPU_S:g} s of CPU "
                                "(the limit of repairing a DBC); fix the overlapping or misplaced signals it "
                                f"reported first: {repairs[0].message}", code="database_too_complex")
        try:
            with _CantoolsNotes() as notes:
                db = cantools.database.load_string(doc.text(), database_format="dbc", strict=True)
        except Exception as exc:  # wrapped or repaired below
            # cantools' grammar needs BU_ (and BS_ in some positions); add them only when parsing fails.
            if tolerant and not sections_checked and "Invalid syntax" in str(exc):
                sections_checked = True
                if _insert_missing_sections(doc, repairs):
                    continue
            if not (tolerant and _repair_from_error(doc, exc, repairs)):
                raise _dbc_error(src, doc, exc) from exc
            continue
        if not isinstance(db, CanDatabase):  # pragma: no cover - load_string with dbc returns a CAN db
            raise DatabaseError(f"{src}: not a CAN database")
        if repairs and not db.messages:  # repairs make a damaged database usable, never an empty one
            raise DatabaseError(f"{src}: defines no messages (no BO_ lines) and is not valid DBC as written: "
                                f"{'; '.join(r.message for r in repairs)}", code="empty_database")
        return LoadedDatabase(db, src, "dbc", repairs, encoding, notes.notes())
    raise DatabaseError(f"{src}: gave up after {_MAX_REPAIR_ROUNDS} repairs; the file is too broken to load")


def _check_layout(src: Path, doc: _DbcText) -> None:
    """Refuse a DBC whose messages carry more signals than any frame can (before cantools parses it)."""
    for name, line, signals in doc.messages().values():
        if len(signals) > MAX_SIGNALS_PER_MESSAGE:
            raise DatabaseError(f"{src}: message {name} (line {doc.origin[line]}) has {len(signals)} signals, more "
                                f"than the {MAX_SIGNALS_PER_MESSAGE} a database may give one message",
                                code="database_too_complex")


def _repair_from_error(doc: _DbcText, exc: Exception, repairs: list[Repair]) -> bool:
    """Fix the one defect cantools complained about; False when it is not repairable."""
    reason = _reason(exc)
    m = _RE_NOT_FIT.search(reason)
    if m:
        sig, msg = m.group(1), m.group(2)
        idx = doc.find_signal(msg, sig)
        if idx is None:
            return False
        repairs.append(Repair("signal_outside", doc.origin[idx],
                              f"signal {sig} does not fit in message {msg}; signal dropped"))
        doc.drop(idx)
        _drop_unused_vals(doc, repairs)
        return True
    m = _RE_OVERLAP.search(reason)
    if m:
        first, second, msg = m.group(1), m.group(2), m.group(3)
        idx = doc.find_signal(msg, second)
        if idx is None:
            return False
        repairs.append(Repair("signal_overlap", doc.origin[idx],
                              f"signals {first} and {second} overlap in message {msg}; {second} dropped"))
        doc.drop(idx)
        _drop_unused_vals(doc, repairs)
        return True
    if "unused VAL_" in reason:
        before = len(repairs)
        _drop_unused_vals(doc, repairs)
        return len(repairs) > before
    return False


def _dbc_error(src: Path, doc: _DbcText, exc: Exception) -> DatabaseError:
    reason = _reason(exc)
    m = _RE_SYNTAX_LINE.search(reason)
    if m:
        line = doc.original_line(int(m.group(1)))
        where = f"line {line}" if line is not None else "an inserted line"
        reason = _RE_SYNTAX_LINE.sub(where, reason, count=1)
        return DatabaseError(f"{src}:{line or '?'}: cannot load DBC: {reason}")
    for pattern, group in ((_RE_NOT_FIT, (2, 1)), (_RE_OVERLAP, (3, 2))):
        m = pattern.search(reason)
        if m:
            idx = doc.find_signal(m.group(group[0]), m.group(group[1]))
            line = doc.origin[idx] if idx is not None else None
            return DatabaseError(f"{src}:{line or '?'}: cannot load DBC: {reason}")
    listed = set(re.findall(r"VAL_ (\d+) (\w+)", reason))
    if listed:
        for i, ln in enumerate(doc.lines):
            vm = _RE_VAL.match(ln)
            if vm and (vm.group(1), vm.group(2)) in listed:
                return DatabaseError(f"{src}:{doc.origin[i] or '?'}: cannot load DBC: {reason}")
    m = re.search(r"in message (\w+)", reason)
    if m:
        for _fid, (name, idx, _sigs) in doc.messages().items():
            if name == m.group(1):
                return DatabaseError(f"{src}:{doc.origin[idx] or '?'}: cannot load DBC: {reason}")
    return DatabaseError(f"{src}: cannot load DBC: {reason}")
