"""The time zone of a log's wall clock, named by the uploader (``tz`` at ``POST /logs``).

Many loggers write their start time as a local wall clock without saying which zone (an ASC
``date`` line, a TRC header, a BLF's SYSTEMTIME): that time is stored as logged and shown as
"log clock". An uploader who knows the zone names it, and the stored start becomes UTC (ISO 8601
with ``+00:00``), so absolute UTC stamps are available beside the seconds from the log start. A
start that carries its own zone (MF4, epoch stamps of candump or GVRET) is kept as the log says.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime, timedelta, timezone, tzinfo
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

from app.errors import InputError

TZ_DOC = ("time zone of the log's wall clock when the log does not record one: an IANA name "
          "(Europe/Berlin) or a UTC offset (+02:00); the start time is then stored in UTC")
_OFFSET = re.compile(r"^(?:UTC)?([+-])(\d{2}):?(\d{2})$")


def time_zone(name: str) -> tzinfo:
    """``name`` as a zone: IANA (``Europe/Berlin``, ``UTC``) or an offset (``+02:00``, ``-0530``, ``UTC+01:00``).

    400 ``bad_time_zone`` for anything else."""
    name = name.strip()
    if m := _OFFSET.match(name):
        minutes = int(m.group(2)) * 60 + int(m.group(3))
        if minutes >= 24 * 60:
            raise InputError(f"time zone {name!r}: offset beyond 23:59", code="bad_time_zone")
        return timezone(timedelta(minutes=-minutes if m.group(1) == "-" else minutes))
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError) as exc:
        raise InputError(f"unknown time zone {name!r}: give an IANA name such as Europe/Berlin or an offset "
                         "such as +02:00", code="bad_time_zone") from exc


def zoned_start(start: str | None, zone: tzinfo | None) -> str | None:
    """The log's start (ISO 8601) in UTC when it has no zone of its own and ``zone`` names its clock."""
    if start is None or zone is None:
        return start
    t = datetime.fromisoformat(start)
    if t.tzinfo is not None:
        return start  # the log's own zone stands
    return t.replace(tzinfo=zone).astimezone(UTC).isoformat()
