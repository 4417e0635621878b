"""Propose signal-map candidates from a database when a vehicle has no map yet.

Each signal is scored per canonical channel from its name (keywords such as ``torque``/``trq``
together with ``motor``/``mcu``/``di``), its unit (convertible to the channel's unit), its
range, and the message rate (DBC cycle time, or the observed period when bus statistics are
given): drive-unit channels want 100 Hz or faster. Words that mark requests, limits and
counters (``req``, ``limit``, ``max``, ``crc``...) count against a signal.

When a log was read, only messages it carries with at least ``MIN_FRAMES`` frames are
proposed (a DBC describes every message the car can send, a log only some). Wheel corners
are read from the names (``FL``/``RR`` codes, ``Front``/``Rear`` with ``Left``/``Right``,
or a node name ending in the code, ``WSBFL``): a signal only ever serves its own corner,
and a corner signal is never the vehicle or motor speed.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message
from cantools.database.can import Signal as CanSignal

from app.ingest.signalmap import CANONICAL, ChannelSpec, SignalMap, unit_factor
from app.ingest.stats import IdStats

_WORDS = re.compile(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+")
_NEGATIVE = {"req", "request", "cmd", "command", "limit", "lim", "max", "min", "target", "set", "setpoint",
             "crc", "checksum", "counter", "alive", "cnt", "status", "stat", "valid", "qf", "flag", "fault",
             "err", "error", "offset", "temp", "temperature", "voltage", "current", "power", "gain", "mode",
             "hvac", "blower", "fan", "pump", "compressor", "liftgate", "window", "seat", "wiper", "mirror",
             "steering", "stw", "angl", "hash", "git", "version", "desired", "slave", "available", "avail",
             "capability", "regen"}
MIN_FRAMES = 20  # a message seen fewer times in the log cannot carry a channel worth analysing

# channel -> (words that must all be present, any-of groups); each group adds to the score
_RULES: dict[str, list[tuple[set[str], float]]] = {
    "motor_torque_nm": [({"torque", "trq", "tq", "tork"}, 3.0), ({"motor", "mot", "mtr", "mcu", "di", "dir",
                        "inv", "inverter", "em", "edu", "drive", "axle", "mg", "mgu", "generator", "emachine"}, 2.0),
                        ({"actual", "act", "est", "estimate", "ist", "feedback", "fb", "fdbk"}, 1.0)],
    "motor_speed_rpm": [({"speed", "spd", "rpm", "n", "velocity", "revolution", "revolutions", "rev", "revs",
                          "rotation", "rotational"}, 3.0),
                        ({"motor", "mot", "mtr", "mcu", "di", "dir", "rotor", "inv", "em", "edu", "axle", "shaft",
                          "mg", "mgu", "generator", "emachine"}, 2.0), ({"actual", "act", "rpm"}, 1.0)],
    "pedal_pct": [({"pedal", "ped", "accel", "throttle", "accelerator", "apedal"}, 3.0),
                  ({"pos", "position", "pct", "travel", "rate"}, 1.0)],
    "vehicle_speed_kmh": [({"speed", "spd", "velocity", "vel", "kph"}, 3.0),
                          ({"vehicle", "veh", "car", "ego", "display", "disp"}, 2.0)],
    "brake": [({"brake", "brk"}, 3.0), ({"pressure", "press", "pres", "pedal", "travel", "force"}, 1.5)],
    "brake_pressed": [({"brake", "brk"}, 3.0), ({"pressed", "switch", "sw", "applied", "status", "on"}, 1.5)],
    "accel_long_ms2": [({"accel", "acc", "acceleration", "ax", "longaccel", "accx"}, 3.0),
                       ({"long", "lon", "lng", "longitudinal", "x"}, 2.0)],
}
_WHEEL = {"wheel", "whl", "wh", "ws", "wheelspeed"}
for _corner in ("fl", "fr", "rl", "rr"):
    _RULES[f"wheel_speed_{_corner}_rpm"] = [(_WHEEL, 3.0), ({"speed", "spd", "rpm", "velocity"}, 1.0)]
_CORNER_CODES = {"fl": "fl", "lf": "fl", "fr": "fr", "rf": "fr", "rl": "rl", "lr": "rl", "rr": "rr"}
_AXLE = {"front": "f", "frt": "f", "rear": "r", "rr": "r"}
_SIDE = {"left": "l", "lh": "l", "right": "r", "rh": "r"}
_NODE = re.compile(r"[A-Z]{2,}(FL|FR|RL|RR)(?![A-Za-z])")  # a node name ending in a corner code: WSBFL
# a rotational speed written in a name or comment: "[rpm]", "in 1/min", "U/min", "rev/min", "rad/s"
_SPEED_UNIT_TEXT = re.compile(r"(?<![A-Za-z])(rpm|1/min|u/min|r/min|rev/min|min-1|min\^-1|rad/s)(?![A-Za-z])", re.I)
# channels whose defining word a rotational-speed unit stands in for (a speed named "Revolution", "N_Out" ...)
_SPEED_CHANNELS = ("motor_speed_rpm",)


@dataclass(frozen=True, slots=True)
class Candidate:
    channel: str
    message: str
    frame_id: int
    signal: str
    unit: str
    score: float
    reasons: tuple[str, ...]


def _words(name: str) -> set[str]:
    out: set[str] = set()
    for part in re.split(r"[^A-Za-z0-9]+", name):
        out.update(w.lower() for w in _WORDS.findall(part))
        out.add(part.lower())
    return out


def corner(name: str) -> str | None:
    """The wheel corner a name speaks of (``"fl"``, ``"fr"``, ``"rl"``, ``"rr"``), ``"f"``/``"r"`` for
    an axle or ``"l"``/``"r"`` sides only (as ``"-l"``/``"-r"``), or None when it names no corner."""
    tokens = [w.lower() for part in re.split(r"[^A-Za-z0-9]+", name) for w in _WORDS.findall(part)]
    for t in tokens:
        if t in _CORNER_CODES:
            return _CORNER_CODES[t]
    axle = next((_AXLE[t] for t in tokens if t in _AXLE), None)
    side = next((_SIDE[t] for t in tokens if t in _SIDE), None)
    if axle and side:
        return axle + side
    node = _NODE.search(name)
    if node:
        return node.group(1).lower()
    return axle or (f"-{side}" if side else None)


def _corner_of(msg: Message, sig: CanSignal) -> str | None:
    """The signal's corner; the message's (its node, e.g. ``WSBFL_Sensors``) when the signal names none."""
    return corner(sig.name) or corner(msg.name)


def _speed_unit(sig: CanSignal, comment: str) -> str | None:
    """Why a signal is a rotational speed by its unit (``unit 'rpm'``), or by a speed unit written in its name
    (``MG_OutputRevolution [rpm]``) or comment; None when neither says so."""
    if sig.unit and unit_factor(sig.unit, "rpm") is not None:
        return f"unit {sig.unit!r} is a rotational speed"
    for where, text in (("name", sig.name), ("comment", comment)):
        if text and (m := _SPEED_UNIT_TEXT.search(text)):
            return f"{where} gives the unit {m.group(1)!r}"
    return None


def _score(channel: str, msg: Message, sig: CanSignal, period_s: float | None) -> tuple[float, list[str]]:
    words = _words(sig.name) | {f"msg:{w}" for w in _words(msg.name)}
    plain = {w for w in words if not w.startswith("msg:")}
    msg_words = {w[4:] for w in words if w.startswith("msg:")}
    score, reasons = 0.0, []
    place = _corner_of(msg, sig)
    if channel.startswith("wheel_speed_"):
        want = channel.split("_")[2]
        if place != want:
            return 0.0, []  # another corner, an axle or side only, or no corner at all
        score += 3.0
        reasons.append(f"corner {want.upper()}")
    comment = sig.comment if isinstance(sig.comment, str) else ""
    note_words = _words(comment) if comment else set()
    for k, (group, weight) in enumerate(_RULES[channel]):
        if plain & group:
            score += weight
            reasons.append(f"name has {sorted(plain & group)[0]!r}")
        elif k == 0 and channel in _SPEED_CHANNELS and (speed_unit := _speed_unit(sig, comment)):
            score += weight  # the unit says what the name does not: a rotational speed
            reasons.append(speed_unit)
        elif msg_words & group:
            score += weight * 0.5
            reasons.append(f"message name has {sorted(msg_words & group)[0]!r}")
        elif note_words & group:
            score += weight * 0.5
            reasons.append(f"comment has {sorted(note_words & group)[0]!r}")
    if score < 3.0:
        return 0.0, []  # the defining keyword is missing
    unit, _, _ = CANONICAL[channel]
    if unit and sig.unit:
        if unit_factor(sig.unit, unit) is not None:
            score += 2.0
            reasons.append(f"unit {sig.unit!r}")
        else:
            score -= 3.0
            reasons.append(f"unit {sig.unit!r} does not convert to {unit!r}")
    bad = plain & _NEGATIVE
    if bad:
        score -= 2.5
        reasons.append(f"name has {sorted(bad)[0]!r}")
    if channel in ("brake_pressed",) and sig.length <= 2:
        score += 1.0
    if channel == "brake" and sig.length <= 2:
        score -= 1.0
    if channel.startswith(("motor_", "pedal", "vehicle_")) and sig.length < 6:
        score -= 2.0
    if channel in ("vehicle_speed_kmh", "motor_speed_rpm") and (plain & _WHEEL or (place and len(place) == 2
                                                                                  and place[0] != "-")):
        score -= 3.0
        reasons.append("a wheel's signal")
    if channel.startswith("motor_"):
        period = period_s if period_s is not None else (msg.cycle_time / 1000.0 if msg.cycle_time else None)
        if period is not None:
            fast = period <= 0.0205
            score += 1.0 if fast else -1.0
            reasons.append(f"period {period * 1000:.0f} ms")
    return score, reasons


def observed(ids: Iterable[IdStats]) -> tuple[dict[int, float], dict[int, int]]:
    """Mean period (s) and frame count by frame ID of the database messages a decode report saw."""
    periods: dict[int, float] = {}
    counts: dict[int, int] = {}
    for i in ids:
        if i.message:
            counts[i.arb_id] = counts.get(i.arb_id, 0) + i.count
            if i.period_ms:
                periods[i.arb_id] = i.period_ms / 1000.0
    return periods, counts


def suggest_candidates(db: CanDatabase, frames_stats: Mapping[int, float] | None = None,
                       limit: int = 5, *, counts: Mapping[int, int] | None = None,
                       min_frames: int = MIN_FRAMES) -> dict[str, list[Candidate]]:
    """Best-scoring signals for each canonical channel.

    Parameters
    ----------
    db
        The database to search.
    frames_stats
        Optional observed mean period in s by frame ID (from a decode report), preferred over
        the DBC's cycle time.
    limit
        Candidates kept per channel.
    counts
        Frames per frame ID in the log (:func:`observed`). When given, messages with fewer
        than ``min_frames`` frames (absent ones included) are not proposed.
    """
    out: dict[str, list[Candidate]] = {}
    messages = [m for m in db.messages if counts is None or counts.get(m.frame_id, 0) >= min_frames]
    for channel in CANONICAL:
        if channel not in _RULES:  # the time base is chosen by hand: any counter would look like one
            continue
        found = []
        for msg in messages:
            period = frames_stats.get(msg.frame_id) if frames_stats else None
            for sig in msg.signals:
                score, reasons = _score(channel, msg, sig, period)
                if score > 0:
                    found.append(Candidate(channel, msg.name, msg.frame_id, sig.name, sig.unit or "",
                                           round(score, 2), tuple(reasons)))
        found.sort(key=lambda c: (-c.score, c.message, c.signal))
        out[channel] = found[:limit]
    return out


def suggest_signal_map(db: CanDatabase, frames_stats: Mapping[int, float] | None = None,
                       min_score: float = 5.0, *, counts: Mapping[int, int] | None = None) -> SignalMap:
    """A draft map from the best candidate of each channel that scores at least ``min_score``.

    A draft: check it (``SignalMap.to_toml()``) before trusting it; the signs and units of
    production DBCs are often undocumented. ``counts`` restricts it to messages in the log
    (see :func:`suggest_candidates`).
    """
    channels: dict[str, ChannelSpec] = {}
    used: set[tuple[str, str]] = set()
    for channel, cands in suggest_candidates(db, frames_stats, counts=counts).items():
        for c in cands:
            if c.score >= min_score and (c.message, c.signal) not in used:
                channels[channel] = ChannelSpec(channel, c.message, c.signal)
                used.add((c.message, c.signal))
                break
    return SignalMap("suggested", channels, notes=["drafted from signal names, units and rates; check before use"])
