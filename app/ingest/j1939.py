"""SAE J1939 addressing: frames match database messages by parameter group number (PGN).

A J1939 29-bit identifier is ``priority (3 bits) | EDP, DP (2) | PF (8) | PS (8) | SA (8)``.
A DBC lists each parameter group once, with whatever priority and source address the
author's ECU used, but on the bus the same group arrives with other priorities and from
other sources; for PDU1 groups (PF < 240) PS is the destination address, which varies too.
So a frame belongs to a J1939 message when the PGNs agree: priority and source address
masked, and for PDU1 the destination address masked as well (the rule of SAE J1939-21 and
of asammdf's ``extract_bus_logging``).

A database is treated as J1939 when it says so: the global ``ProtocolType "J1939"``
attribute, or messages whose ``VFrameFormat`` is ``J1939PG`` (cantools' ``protocol ==
"j1939"``). Only extended-ID messages take part; an exact ID match still wins.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import numpy.typing as npt
from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message

PDU2_MIN_PF = 240  # PF >= 240: PDU2, PS is a group extension (part of the PGN)


def pgn(arb_id: int) -> int:
    """The PGN of a 29-bit identifier (priority, source and, for PDU1, destination masked)."""
    pf = (arb_id >> 16) & 0xFF
    group = (arb_id >> 8) & 0x3FFFF
    return group if pf >= PDU2_MIN_PF else group & 0x3FF00


def pgns(arb_id: npt.NDArray[np.integer]) -> npt.NDArray[np.int64]:
    """:func:`pgn` of every identifier of an array."""
    ids = arb_id.astype(np.int64)
    group = (ids >> 8) & 0x3FFFF
    return np.where(((ids >> 16) & 0xFF) >= PDU2_MIN_PF, group, group & 0x3FF00)


def database_is_j1939(db: CanDatabase) -> bool:
    """True when the database declares J1939 (globally or for any message)."""
    return _global_protocol(db) or any(m.protocol == "j1939" for m in db.messages)


def _global_protocol(db: CanDatabase) -> bool:
    attrs = getattr(getattr(db, "dbc", None), "attributes", None) or {}
    protocol = attrs.get("ProtocolType")
    return protocol is not None and str(getattr(protocol, "value", "")).strip().lower() == "j1939"


def j1939_messages(db: CanDatabase, messages: Iterable[Message] | None = None) -> dict[int, Message]:
    """PGN -> message for the J1939 extended-ID messages (first one per PGN); {} when there are none.

    With the global ``ProtocolType "J1939"`` every extended-ID message takes part, otherwise
    only the messages marked ``J1939PG``.
    """
    every = _global_protocol(db)
    table: dict[int, Message] = {}
    for m in db.messages if messages is None else messages:
        if m.is_extended_frame and (every or m.protocol == "j1939"):
            table.setdefault(pgn(m.frame_id), m)
    return table
