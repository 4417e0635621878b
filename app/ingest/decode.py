"""Vectorized CAN message decoding: numpy over the frames of one message ID at a time.

The decoder gives the same numbers as ``cantools.database.Database.decode_message(frame_id,
data, decode_choices=False)`` for every frame, as float64:

* bit layouts: little-endian (Intel) and big-endian (Motorola) signals of 1..64 bits anywhere
  in a classic (8 byte) or CAN FD (up to 64 byte) payload; signed two's complement;
  IEEE float16/32/64 signals.
* scaling: the same arithmetic as cantools' conversion classes, so integer results (identity
  or integer scale and offset, computed exactly by cantools) and float results (``raw * scale +
  offset`` in double precision) match bit for bit. Where int64/float64 arithmetic could differ
  from Python's unbounded integers (very wide signals), Python integers are used.
* multiplexing, including extended multiplexing (cascaded and independent multiplexers, several
  multiplexer values per signal): the codec tree cantools builds is walked with row masks.
  Frames whose multiplexer value has no branch are errors (cantools raises); they are counted
  under ``unknown_mux`` and left out.
* short frames (fewer bytes than the message length): cantools raises unless
  ``allow_truncated``; by default they are counted under ``short_frame`` and left out. With
  ``allow_truncated=True`` the signals lying wholly inside the received bytes are decoded and
  the others are absent, as in cantools. Longer frames are decoded from their first bytes
  (cantools' ``allow_excess``).
* error and remote frames are never decoded; frames match a message by ID *and* the
  extended-ID flag. In a J1939 database an extended frame that matches no ID exactly matches
  by PGN (priority, source and PDU1 destination address masked; :mod:`app.ingest.j1939`).

Signals absent from a frame (another multiplexer branch, beyond a truncated payload) are NaN
and ``DecodedMessage.present`` says so. Enumerations stay numeric; values whose label means
"not available" (see :func:`is_na_label`) become NaN when ``na_to_nan``.

Messages the fast path does not cover (container PDUs) are skipped, like cantools' default;
no signal layout cantools accepts needs a per-frame fallback, which exists for safety only.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message
from cantools.database.can import Signal as CanSignal
from cantools.database.conversion import BaseConversion, IdentityConversion, LinearIntegerConversion

from app.ingest.bitfields import SignalLayout, extract_raw
from app.ingest.frames import EXTENDED_KEY, SMALL_CHUNK, FrameChunk, FrameGroups, distinct, frame_groups
from app.ingest.j1939 import j1939_messages, pgn

F64 = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
_IDENTITY, _PYTHON, _INTEGER, _FLOAT = range(4)  # scaling arithmetic, see _scale

NA_LABELS: tuple[str, ...] = (
    "sna", "signal not available", "not available", "n/a", "na", "unavailable",
    "invalid", "error", "init", "initializing", "initialising",
)


def is_na_label(label: str, patterns: Sequence[str] = NA_LABELS) -> bool:
    """True when an enumeration label means "no valid value".

    Case-insensitive; punctuation and underscores count as spaces. A label matches when it
    equals a pattern or ends with a one-word pattern (``DI_TORQUE_SNA``), unless it starts
    with a negation (``No_Error``, ``not_init``).
    """
    norm = " ".join(re.sub(r"[^a-z0-9/]+", " ", str(label).lower()).split())
    pats = {" ".join(re.sub(r"[^a-z0-9/]+", " ", p.lower()).split()) for p in patterns}
    if norm in pats:
        return True
    words = norm.split()
    if len(words) < 2 or words[0] in ("no", "not", "non"):
        return False
    return words[-1] in pats


@dataclass(slots=True)
class DecodedMessage:
    """Decoded frames of one message: one row per decoded frame.

    Arrays all have shape ``(n,)``; ``signals`` are float64 physical values (NaN when absent
    or not available). ``errors`` counts frames left out, by reason.
    """

    name: str
    frame_id: int
    is_extended: bool
    t_ns: npt.NDArray[np.int64]
    channel: npt.NDArray[np.int16]
    signals: dict[str, F64]
    present: dict[str, BoolArray] = field(default_factory=dict)  # only signals that can be absent
    errors: dict[str, int] = field(default_factory=dict)

    def __len__(self) -> int:
        return int(self.t_ns.size)

    def is_present(self, signal: str) -> BoolArray:
        """Rows where ``signal`` was in the frame (multiplexed/truncated signals can be absent)."""
        got = self.present.get(signal)
        return got if got is not None else np.ones(self.t_ns.size, bool)

    @staticmethod
    def concat(parts: Sequence[DecodedMessage]) -> DecodedMessage:
        """Join the results of several chunks for the same message."""
        first = parts[0]
        errors: dict[str, int] = {}
        for p in parts:
            for k, v in p.errors.items():
                errors[k] = errors.get(k, 0) + v
        present_names = {k for p in parts for k in p.present}
        return DecodedMessage(
            first.name, first.frame_id, first.is_extended,
            np.concatenate([p.t_ns for p in parts]), np.concatenate([p.channel for p in parts]),
            {k: np.concatenate([p.signals[k] for p in parts]) for k in first.signals},
            {k: np.concatenate([p.is_present(k) for p in parts]) for k in present_names},
            errors,
        )


class NaMatch:
    """Which raw values of one signal are labelled "not available", decided with one or two numpy operations.

    Built once per signal (the decoder calls it for every batch, and a live batch is ~20
    frames, so per-call setup would dominate): a single value is one comparison; integer
    signals of up to ``TABLE_BITS`` bits use a lookup table over the raw bit pattern; the
    rest a sorted array and ``searchsorted``. Values are compared exactly in the raw dtype
    (float signals as float64), like ``np.isin``.
    """

    TABLE_BITS = 12

    __slots__ = ("_mask", "_one", "_sorted", "_table", "empty")

    def __init__(self, values: Sequence[int | float], layout: SignalLayout) -> None:
        self._one: int | float | None = None
        self._table: npt.NDArray[np.bool_] | None = None
        self._sorted: npt.NDArray[np.generic] | None = None
        self._mask = np.uint64((1 << layout.length) - 1) if layout.length < 64 else np.uint64(2**64 - 1)
        if layout.float_bits:
            vals: list[int | float] = sorted({float(v) for v in values})
        else:  # an integer signal never equals a fractional value; out-of-range ones never match
            lo, hi = (-(2 ** (layout.length - 1)), 2 ** (layout.length - 1)) if layout.signed else (0, 2**layout.length)
            vals = sorted({int(v) for v in values if float(v).is_integer() and lo <= int(v) < hi})
        self.empty = not vals
        if len(vals) == 1:
            self._one = vals[0]
        elif vals and not layout.float_bits and layout.length <= self.TABLE_BITS:
            self._table = np.zeros(1 << layout.length, bool)
            self._table[[int(v) & int(self._mask) for v in vals]] = True
        elif vals:
            dtype = np.float64 if layout.float_bits else (np.int64 if layout.signed else np.uint64)
            self._sorted = np.asarray(vals, dtype)

    def __call__(self, raw: npt.NDArray[np.generic]) -> BoolArray:
        """``(n,)`` True where ``raw`` (``(n,)``, as :func:`extract_raw` gives it) is not available."""
        if self._one is not None:
            return np.asarray(raw == self._one)
        if self._table is not None:
            bits = raw if raw.dtype.kind == "u" else raw.view(np.uint64)
            return self._table[np.bitwise_and(bits, self._mask)]
        assert self._sorted is not None
        i = np.searchsorted(self._sorted, raw)
        return np.asarray(self._sorted[np.minimum(i, self._sorted.size - 1)] == raw)


@dataclass(slots=True)
class _SignalPlan:
    name: str
    layout: SignalLayout
    conversion: BaseConversion  # without choices: decides the arithmetic
    na_raw: tuple[int | float, ...]  # raw values labelled not-available (empty when none / disabled)
    exact_float: bool  # float64 arithmetic reproduces cantools' result exactly
    na: NaMatch | None = None  # None when no raw value is "not available"
    arithmetic: int = _FLOAT  # which branch of :func:`_scale` (decided once, not per batch)


@dataclass(slots=True)
class _Node:
    signals: list[_SignalPlan]
    muxes: dict[str, dict[int, _Node]]


@dataclass(slots=True)
class _MessagePlan:
    message: Message
    root: _Node
    plans: dict[str, _SignalPlan]
    padded_len: int  # message length rounded up to whole 64-bit words
    maybe_absent: set[str]
    out_name: str = ""  # the message name, made unique when a database reuses names
    flat: bool = False  # no multiplexing and no truncation: every signal decodes from every frame


class VectorDecoder:
    """Decode :class:`FrameChunk` objects with numpy, message by message.

    Parameters
    ----------
    db
        A cantools CAN database.
    na_to_nan
        Turn raw values whose enumeration label means "not available" into NaN.
    na_labels
        The labels meaning "not available" (see :func:`is_na_label`).
    allow_truncated
        Decode the complete signals of short frames instead of leaving the frames out.
    messages
        Only decode these messages (names or frame IDs); all when None.
    """

    def __init__(self, db: CanDatabase, *, na_to_nan: bool = True, na_labels: Sequence[str] = NA_LABELS,
                 allow_truncated: bool = False, messages: Iterable[str | int] | None = None) -> None:
        self.db = db
        self.na_to_nan = na_to_nan
        self.na_labels = tuple(na_labels)
        self.allow_truncated = allow_truncated
        wanted = None if messages is None else set(messages)
        self._plans: dict[int, _MessagePlan] = {}
        self.skipped: dict[str, str] = {}  # message name -> why it is not decoded
        for msg in db.messages:
            if wanted is not None and msg.name not in wanted and msg.frame_id not in wanted:
                continue
            if msg.is_container:
                self.skipped[msg.name] = "container message (not decoded, as cantools' default)"
                continue
            key = msg.frame_id | (EXTENDED_KEY if msg.is_extended_frame else 0)
            self._plans[key] = self._plan(msg)  # a later message with the same ID wins, as in cantools
        # J1939 databases: frames whose ID matches no message exactly match by PGN (app.ingest.j1939)
        self._by_pgn = {pgn: m.frame_id | EXTENDED_KEY for pgn, m in
                        j1939_messages(db, [p.message for p in self._plans.values()]).items()}
        self._resolved: dict[int, int | None] = {}  # frame key -> plan key (cache of :meth:`_plan_key`)
        names = [p.message.name for p in self._plans.values()]
        for p in self._plans.values():
            dup = names.count(p.message.name) > 1
            p.out_name = f"{p.message.name}@0x{p.message.frame_id:X}" if dup else p.message.name

    # -- planning -------------------------------------------------------------------------
    def labels(self, message: str) -> dict[str, dict[int, str]]:
        """Enumeration labels by signal for ``message`` (raw value -> label)."""
        msg = self.db.get_message_by_name(message)
        return {s.name: {int(k): str(v) for k, v in (s.choices or {}).items()} for s in msg.signals}

    def _plan(self, msg: Message) -> _MessagePlan:
        plans = {s.name: self._signal_plan(s) for s in msg.signals}
        root = self._node(msg, None, None, plans)
        maybe_absent = {s.name for s in msg.signals if s.multiplexer_signal is not None}
        if self.allow_truncated:
            maybe_absent = set(plans)
        padded = max(8, -(-msg.length // 8) * 8)
        flat = not root.muxes and not self.allow_truncated
        return _MessagePlan(msg, root, plans, padded, maybe_absent, flat=flat)

    def _node(self, msg: Message, parent: str | None, mux_id: int | None, plans: dict[str, _SignalPlan]) -> _Node:
        # Mirrors cantools' Message._create_codec so branches (and errors) match it exactly.
        node = _Node([], {})
        for s in msg.signals:
            if s.multiplexer_signal != parent:
                continue
            if mux_id is not None and (s.multiplexer_ids is None or mux_id not in s.multiplexer_ids):
                continue
            if s.is_multiplexer:
                ids: set[int] = set()
                for child in msg.signals:
                    if child.multiplexer_signal == s.name and child.multiplexer_ids is not None:
                        ids.update(child.multiplexer_ids)
                if s.conversion.choices:
                    ids.update(int(k) for k in s.conversion.choices)
                node.muxes[s.name] = {i: self._node(msg, s.name, i, plans) for i in ids}
            node.signals.append(plans[s.name])
        return node

    def _signal_plan(self, s: CanSignal) -> _SignalPlan:
        conv = BaseConversion.factory(scale=s.conversion.scale, offset=s.conversion.offset,
                                      choices=None, is_float=s.conversion.is_float)
        layout = SignalLayout.of(s.start, s.length, s.byte_order == "big_endian", s.is_signed,
                                 s.length if s.conversion.is_float else 0)
        na = tuple(k for k, v in (s.conversion.choices or {}).items()
                   if self.na_to_nan and is_na_label(str(v), self.na_labels))
        max_raw = 2 ** (s.length - (1 if s.is_signed else 0))
        if conv.is_float or isinstance(conv, IdentityConversion):
            exact = True  # float raw: double arithmetic as in Python; identity: int -> float rounding only
        elif isinstance(conv, LinearIntegerConversion):
            exact = max_raw * abs(conv.scale) + abs(conv.offset) < 2**63
        else:  # float scale: Python converts the raw int to float first, like numpy
            exact = isinstance(conv.scale, float) or max_raw * abs(conv.scale) < 2**53
        match = NaMatch(na, layout) if na else None
        arithmetic = (_IDENTITY if isinstance(conv, IdentityConversion) else _PYTHON if not exact
                      else _INTEGER if isinstance(conv, LinearIntegerConversion) else _FLOAT)
        return _SignalPlan(s.name, layout, conv, na, exact, None if match is None or match.empty else match, arithmetic)

    # -- decoding -------------------------------------------------------------------------
    def decode(self, chunk: FrameChunk, groups: FrameGroups | None = None) -> dict[str, DecodedMessage]:
        """Decode every frame of ``chunk`` that belongs to a database message.

        ``groups``: the chunk's :func:`~app.ingest.frames.frame_groups` when the caller has them.

        Returns
        -------
        dict
            Message name -> :class:`DecodedMessage` (frames in chunk order). Messages with no
            frames in the chunk are absent; messages whose frames all failed have zero rows
            and their ``errors``.
        """
        if len(chunk) == 0 or not self._plans:
            return {}
        # key = ID | extended << 31, with bit 30 set for error/remote frames so they match no message
        groups = self._match(frame_groups(chunk) if groups is None else groups)
        out: dict[str, DecodedMessage] = {}
        with np.errstate(all="ignore"):  # inf/NaN float signals scale like Python floats, silently
            for k, idx in groups:
                plan = self._plans[k]
                out[plan.out_name] = self._decode_rows(plan, chunk, idx)
        return out

    def plan_key(self, key: int) -> int | None:
        """The message key a frame key (ID | extended bit 31 | error/remote bit 30) decodes as, or None."""
        if key in self._plans:
            return key
        if not self._by_pgn or not key & EXTENDED_KEY or key & (1 << 30):
            return None
        got = self._resolved.get(key, -1)
        if got == -1:
            got = self._resolved[key] = self._by_pgn.get(pgn(key & 0x1FFF_FFFF))
        return got

    def _match(self, groups: FrameGroups) -> FrameGroups:
        """Frame groups by ID -> row groups by message (J1939: several IDs share one message, rows in order)."""
        if not self._by_pgn:
            return [(k, idx) for k, idx in groups if k in self._plans]
        merged: dict[int, list[npt.NDArray[np.intp]]] = {}
        for k, idx in groups:
            target = self.plan_key(k)
            if target is not None:
                merged.setdefault(target, []).append(idx)
        return [(k, parts[0] if len(parts) == 1 else np.sort(np.concatenate(parts))) for k, parts in merged.items()]

    def _decode_rows(self, plan: _MessagePlan, chunk: FrameChunk, idx: npt.NDArray[np.intp]) -> DecodedMessage:
        msg = plan.message
        n = idx.size
        width = min(chunk.width, plan.padded_len)
        if chunk.width == plan.padded_len:
            payload = chunk.data[idx]
        else:
            payload = np.zeros((n, plan.padded_len), np.uint8)
            payload[:, :width] = chunk.data[idx, :width]
        if plan.flat:
            return self._decode_flat(plan, chunk, idx, payload)
        dlc = chunk.dlc[idx].astype(np.int64)
        errors: dict[str, int] = {}
        ok = np.ones(n, bool)
        short = dlc < msg.length
        if short.any() and not self.allow_truncated:
            errors["short_frame"] = int(short.sum())
            ok &= ~short
        values = {name: np.full(n, np.nan) for name in plan.plans}
        present = {name: np.zeros(n, bool) for name in plan.maybe_absent}
        words: dict[tuple[int, bool], npt.NDArray[np.uint64]] = {}
        avail_bits = dlc * 8
        self._walk(plan.root, np.flatnonzero(ok), payload, words, avail_bits, values, present, ok, errors)
        keep = np.flatnonzero(ok)
        sel = idx[keep]
        return DecodedMessage(
            plan.out_name, msg.frame_id, bool(msg.is_extended_frame), chunk.t_ns[sel], chunk.channel[sel],
            {k: v[keep] for k, v in values.items()}, {k: v[keep] for k, v in present.items()}, errors,
        )

    def _decode_flat(self, plan: _MessagePlan, chunk: FrameChunk, idx: npt.NDArray[np.intp],
                     payload: npt.NDArray[np.uint8]) -> DecodedMessage:
        """A message without multiplexing: every signal straight from every (long enough) frame."""
        msg = plan.message
        errors: dict[str, int] = {}
        dlc = chunk.dlc[idx]
        if min(dlc.tolist()) < msg.length if idx.size <= SMALL_CHUNK else int(dlc.min()) < msg.length:
            ok = dlc >= msg.length
            errors["short_frame"] = int(idx.size - np.count_nonzero(ok))
            idx, payload = idx[ok], payload[ok]
        words: dict[tuple[int, bool], npt.NDArray[np.uint64]] = {}
        values: dict[str, F64] = {}
        for sp in plan.root.signals:
            raw = extract_raw(payload, sp.layout, words)
            scaled = _scale(sp, raw)
            if sp.na is not None:
                scaled[sp.na(raw)] = np.nan
            values[sp.name] = scaled
        return DecodedMessage(plan.out_name, msg.frame_id, bool(msg.is_extended_frame), chunk.t_ns[idx],
                              chunk.channel[idx], values, {}, errors)

    def _walk(self, node: _Node, rows: npt.NDArray[np.intp], payload: npt.NDArray[np.uint8],
              words: dict[tuple[int, bool], npt.NDArray[np.uint64]], avail_bits: npt.NDArray[np.int64],
              values: dict[str, F64], present: dict[str, BoolArray], ok: BoolArray, errors: dict[str, int]) -> None:
        """Decode ``node``'s signals at ``rows`` and recurse into the selected multiplexer branches."""
        if rows.size == 0:
            return
        have: dict[str, BoolArray] = {}
        if rows.size == payload.shape[0]:
            full, cache = payload, words
        else:
            full, cache = payload[rows], {}
        for sp in node.signals:
            raw = extract_raw(full, sp.layout, cache)
            scaled = _scale(sp, raw)
            mux_val = scaled.copy() if sp.name in node.muxes else scaled  # branch on the value before NaN-ing
            if sp.na is not None:
                scaled[sp.na(raw)] = np.nan
            if self.allow_truncated:
                inside = sp.layout.end_bit <= avail_bits[rows]
                scaled[~inside] = np.nan
                have[sp.name] = inside
            values[sp.name][rows] = scaled
            if sp.name in present:
                present[sp.name][rows] = have.get(sp.name, True)
            if sp.name in node.muxes:
                mux_rows, branches = rows, node.muxes[sp.name]
                if self.allow_truncated:
                    mux_rows, mux_val = rows[have[sp.name]], mux_val[have[sp.name]]
                finite = np.isfinite(mux_val)
                bad = ~finite
                number = np.trunc(np.where(finite, mux_val, 0.0))
                for value in distinct(number[finite]):
                    branch = branches.get(int(value))
                    hit = finite & (number == value)
                    if branch is None:
                        bad |= hit
                    else:
                        self._walk(branch, mux_rows[hit], payload, words, avail_bits, values, present, ok, errors)
                if bad.any():
                    errors["unknown_mux"] = errors.get("unknown_mux", 0) + int(bad.sum())
                    ok[mux_rows[bad]] = False


def _scale(sp: _SignalPlan, raw: npt.NDArray[np.generic]) -> F64:
    """Physical values with cantools' arithmetic (``raw * scale + offset``), as float64."""
    conv = sp.conversion
    kind = sp.arithmetic
    if kind == _IDENTITY:
        return raw.astype(np.float64)
    if kind == _PYTHON:
        # Python integers, as cantools computes them, then one rounding to float.
        return np.array([float(int(r) * conv.scale + conv.offset) for r in raw.tolist()], np.float64)
    if kind == _INTEGER:
        return (raw.astype(np.int64) * conv.scale + conv.offset).astype(np.float64)
    out = raw.astype(np.float64) * np.float64(conv.scale)
    out += np.float64(conv.offset)
    return out
