"""What reading a log lost, in a form every result carries: damaged or truncated input is stated
beside the answer (the analysis' summary, the diagnosis, the command line), with frames and seconds lost.

The readers record each problem as a :class:`~app.ingest.frames.ReadIssue`. This module sums them
up: whether the log is damaged and truncated, how many frames were lost (the readers' counts and
estimates; a skipped text line is one frame; a BLF cut short loses what its header counts beyond
what was read) and how many seconds (a BLF header's stop time says how long the measurement
ran; otherwise frames lost at the log's frame rate, marked as an estimate).
"""

from __future__ import annotations

from datetime import datetime
from typing import Any

from app.ingest.frames import IngestReport, LogMeta, ReadIssue
from app.ingest.readers._base import INFO_KINDS as READER_INFO

# what describes the log rather than damage to it; a logger's own DATA_LOST events count as loss here
INFO_KINDS = READER_INFO - {"data_lost"}
LINE_KINDS = frozenset({"bad_line", "non_hex", "short_data", "bad_timestamp"})  # one line = one frame
MAX_LISTED = 20


def _where(i: ReadIssue) -> str:
    if i.line is not None:
        return f"line {i.line}"
    if i.offset is not None:
        return f"byte offset {i.offset}"
    return ""


def _frames_lost(i: ReadIssue) -> int | None:
    if i.frames_lost is not None:
        return i.frames_lost
    return i.count if i.kind in LINE_KINDS else None


def read_summary(meta: LogMeta, report: IngestReport, frames_read: int, duration_s: float) -> dict[str, Any]:
    """The read report of one log as plain data.

    Parameters
    ----------
    meta, report
        The reader's metadata and report after every frame was read.
    frames_read
        Frames delivered.
    duration_s
        Time spanned by the frames read, s.

    Returns
    -------
    dict
        ``damaged``, ``truncated`` (bools), ``frames_read``, ``frames_lost`` (None when unknown),
        ``seconds_lost`` (None when unknown), ``estimated`` (the frames lost are an estimate: a BLF
        header counts every object, a damaged region's frames come from its size),
        ``seconds_estimated`` (the seconds come from the frame rate, not from the log's header),
        ``problems`` (kind, where, count, message, frames_lost, bytes_lost; at most 20, first first)
        and ``note`` (one sentence for people; None for an undamaged log).
    """
    damage = [i for i in report.issues if i.kind not in INFO_KINDS]
    truncated = any(i.kind == "truncated" for i in damage)
    known = [n for n in (_frames_lost(i) for i in damage) if n is not None]
    frames_lost: int | None = sum(known) if known else None
    estimated = any(i.kind not in LINE_KINDS for i in damage)
    declared = meta.extra.get("header_object_count", "")
    if truncated and declared.isdigit() and int(declared) > frames_read:
        # the header counts every object the logger wrote; what was not read is lost (non-CAN objects are
        # few, so this is a close upper estimate)
        frames_lost = max(frames_lost or 0, int(declared) - frames_read)
    seconds_lost: float | None = None
    seconds_estimated = False
    stop = meta.extra.get("stop_time_local")
    if truncated and stop and isinstance(meta.start_time, datetime):
        try:
            measured = (datetime.fromisoformat(stop) - meta.start_time.replace(tzinfo=None)).total_seconds()
        except ValueError:
            measured = 0.0
        if measured > duration_s:
            seconds_lost = measured - duration_s
    if seconds_lost is None and frames_lost and frames_read and duration_s > 0:
        seconds_lost = frames_lost * duration_s / frames_read
        seconds_estimated = True
    problems = [{"kind": i.kind, "where": _where(i), "count": i.count, "message": i.message,
                 "frames_lost": _frames_lost(i), "bytes_lost": i.bytes_lost} for i in damage[:MAX_LISTED]]
    summary: dict[str, Any] = {
        "damaged": bool(damage), "truncated": truncated, "frames_read": frames_read, "frames_lost": frames_lost,
        "seconds_lost": seconds_lost, "estimated": estimated if damage else False,
        "seconds_estimated": seconds_estimated, "problems": problems,
        "problem_count": sum(i.count for i in damage), "note": None,
    }
    if damage:
        summary["note"] = read_note(summary, duration_s)
    return summary


def read_note(s: dict[str, Any], duration_s: float) -> str:
    """One sentence: what is wrong with the log and what it cost, e.g. ``the log is truncated (...); about
    9693 frame(s) (19.4 s) lost; the results cover the 20.6 s that were read``."""
    first = s["problems"][0] if s["problems"] else None
    what = "truncated" if s["truncated"] else "damaged"
    n = s["problem_count"]
    text = f"the log is {what}"
    if first is not None:
        where = f" at {first['where']}" if first["where"] else ""
        more = f"; {n - 1} more problem(s)" if n > 1 else ""
        text += f" ({first['kind']}{where}: {first['message']}{more})"
    about = "about " if s["estimated"] else ""
    if s["frames_lost"] is not None:
        about_s = "about " if s["seconds_estimated"] else ""
        secs = f" ({about_s}{s['seconds_lost']:.1f} s)" if s["seconds_lost"] is not None else ""
        text += f"; {about}{s['frames_lost']} frame(s){secs} lost"
    else:
        text += "; frames lost: unknown"
    return text + f"; the results cover the {duration_s:.1f} s that were read"
