"""Propose signal-map candidates from a database when a vehicle has no map yet.

Each signal is scored per canonical channel from its name (keywords such as ``torque``/``trq``
together with ``motor``/``mcu``/``di``), its unit (convertible to the channel's unit), its
range, and the message rate (DBC cycle time, or the observed period when bus statistics are
given): drive-unit channels want 100 Hz or faster. Words that mark requests, limits and
counters (``req``, ``limit``, ``max``, ``crc``...) count against a signal.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass

from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message
from cantools.database.can import Signal as CanSignal

from app.ingest.signalmap import CANONICAL, ChannelSpec, SignalMap, unit_factor

_WORDS = re.compile(r"[A-Z]?[a-z]+|[A-Z]+(?![a-z])|\d+")
_NEGATIVE = {"req", "request", "cmd", "command", "limit", "lim", "max", "min", "target", "set", "setpoint",
             "crc", "checksum", "counter", "alive", "cnt", "status", "stat", "valid", "qf", "flag", "fault",
             "err", "error", "offset", "temp", "temperature", "voltage", "current", "power", "gain", "mode",
             "hvac", "blower", "fan", "pump", "compressor", "liftgate", "window", "seat", "wiper", "mirror",
             "steering", "stw", "angl", "hash", "git", "version", "desired", "slave"}

# channel -> (words that must all be present, any-of groups); each group adds to the score
_RULES: dict[str, list[tuple[set[str], float]]] = {
    "motor_torque_nm": [({"torque", "trq", "tq", "tork"}, 3.0), ({"motor", "mot", "mtr", "mcu", "di", "dir",
                        "inv", "inverter", "em", "edu", "drive", "axle"}, 2.0), ({"actual", "act", "est", "estimate",
                        "ist"}, 1.0)],
    "motor_speed_rpm": [({"speed", "spd", "rpm", "n", "velocity"}, 3.0), ({"motor", "mot", "mtr", "mcu", "di", "dir",
                        "rotor", "inv", "em", "edu", "axle", "shaft"}, 2.0), ({"actual", "act", "rpm"}, 1.0)],
    "pedal_pct": [({"pedal", "ped", "accel", "throttle", "accelerator", "apedal"}, 3.0),
                  ({"pos", "position", "pct", "travel", "rate"}, 1.0)],
    "vehicle_speed_kmh": [({"speed", "spd", "velocity", "vel", "kph"}, 3.0),
                          ({"vehicle", "veh", "car", "ego", "display", "disp"}, 2.0)],
    "brake": [({"brake", "brk"}, 3.0), ({"pressure", "press", "pres", "pedal", "travel", "force"}, 1.5)],
    "brake_pressed": [({"brake", "brk"}, 3.0), ({"pressed", "switch", "sw", "applied", "status", "on"}, 1.5)],
}
_WHEEL = {"wheel", "whl", "wh", "ws", "wheelspeed"}
for _corner, _corner_words in (("fl", {"fl", "lf"}), ("fr", {"fr", "rf"}), ("rl", {"rl", "lr"}), ("rr", {"rr"})):
    _RULES[f"wheel_speed_{_corner}_rpm"] = [(_WHEEL, 3.0), (_corner_words, 3.0),
                                            ({"speed", "spd", "rpm", "velocity"}, 1.0)]


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


def _score(channel: str, msg: Message, sig: CanSignal, period_s: float | None) -> tuple[float, list[str]]:
    words = _words(sig.name) | {f"msg:{w}" for w in _words(msg.name)}
    plain = {w for w in words if not w.startswith("msg:")}
    msg_words = {w[4:] for w in words if w.startswith("msg:")}
    score, reasons = 0.0, []
    for group, weight in _RULES[channel]:
        if plain & group:
            score += weight
            reasons.append(f"name has {sorted(plain & group)[0]!r}")
        elif msg_words & group:
            score += weight * 0.5
            reasons.append(f"message name has {sorted(msg_words & group)[0]!r}")
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
    if channel.startswith(("motor_", "pedal")) and sig.length < 6:
        score -= 2.0
    if channel == "vehicle_speed_kmh" and plain & _WHEEL:
        score -= 3.0
    if channel.startswith("motor_"):
        if channel == "motor_speed_rpm" and plain & _WHEEL:
            score -= 3.0
        period = period_s if period_s is not None else (msg.cycle_time / 1000.0 if msg.cycle_time else None)
        if period is not None:
            fast = period <= 0.0205
            score += 1.0 if fast else -1.0
            reasons.append(f"period {period * 1000:.0f} ms")
    return score, reasons


def suggest_candidates(db: CanDatabase, frames_stats: Mapping[int, float] | None = None,
                       limit: int = 5) -> dict[str, list[Candidate]]:
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
    """
    out: dict[str, list[Candidate]] = {}
    for channel in CANONICAL:
        found = []
        for msg in db.messages:
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
                       min_score: float = 5.0) -> SignalMap:
    """A draft map from the best candidate of each channel that scores at least ``min_score``.

    A draft: check it (``SignalMap.to_toml()``) before trusting it; the signs and units of
    production DBCs are often undocumented.
    """
    channels: dict[str, ChannelSpec] = {}
    used: set[tuple[str, str]] = set()
    for channel, cands in suggest_candidates(db, frames_stats).items():
        for c in cands:
            if c.score >= min_score and (c.message, c.signal) not in used:
                channels[channel] = ChannelSpec(channel, c.message, c.signal)
                used.add((c.message, c.signal))
                break
    return SignalMap("suggested", channels, notes=["drafted from signal names, units and rates; check before use"])
