"""Signal maps: which DBC signal carries each canonical channel of a vehicle, and how to convert it.

A map is a TOML file, one table per canonical channel::

    [vehicle]
    name = "lashscope reference EV"

    [channels.motor_speed_rpm]
    message = "MCU_Speed"        # message name, or its frame ID as "0x101" / 257
    signal = "MotorSpeed"
    unit = "rad/s"               # optional: the signal's unit when the DBC has none or a wrong one
    factor = 1.0                 # optional extra factor after unit conversion
    offset = 0.0                 # optional, added last
    invert = false               # optional: flip the sign (motor mounted backwards)
    bus = 0                      # optional: only frames from this log channel (0-based)

``time_base`` (optional) is a timer or counter the ECU writes into the motor speed's own message
(an in-payload millisecond timer: ``unit = "ms"``; an alive counter sent every 10 ms:
``unit = "s"``, ``factor = 0.01``); it must be a signal of the same message as
``motor_speed_rpm``, and re-times the speed samples when the logger's stamps are off
(:func:`app.analysis.sampling.timer_times`). Wrap-around is undone from the data.

The physical value becomes ``(-1 if invert else 1) * unit_factor * factor * value + offset`` in
the channel's canonical unit (:data:`CANONICAL`). Units convert between the spellings in
:data:`UNIT_FACTORS`; other units raise :class:`~app.errors.SignalMapError` unless ``factor``
is given together with ``unit = "<canonical unit>"``. Candidate signals for each channel are
proposed by :mod:`app.ingest.suggest`.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from cantools.database.can import Database as CanDatabase
from cantools.database.can import Message
from cantools.database.can import Signal as CanSignal

from app.errors import SignalMapError
from app.signals.signal import Interp

# 1 rad/s in rpm: sim.units.RPM_PER_RAD_S, the same expression (tests/ingest/test_signalmap.py holds them equal), not
# imported from there: importing sim loads the simulator and numba, about half a second of start-up for every
# process that only reads a log (tests/test_import_rules.py keeps app.ingest off sim)
RPM_PER_RAD_S = 30.0 / math.pi

#: Canonical channels: name -> (canonical unit, interpolation, required by the analyses).
CANONICAL: dict[str, tuple[str, Interp, bool]] = {
    "pedal_pct": ("%", Interp.LINEAR, True),
    "motor_torque_nm": ("Nm", Interp.LINEAR, True),
    "motor_speed_rpm": ("rpm", Interp.LINEAR, True),
    "vehicle_speed_kmh": ("km/h", Interp.LINEAR, False),
    "wheel_speed_fl_rpm": ("rpm", Interp.LINEAR, False),
    "wheel_speed_fr_rpm": ("rpm", Interp.LINEAR, False),
    "wheel_speed_rl_rpm": ("rpm", Interp.LINEAR, False),
    "wheel_speed_rr_rpm": ("rpm", Interp.LINEAR, False),
    "brake": ("", Interp.LINEAR, False),  # pressure or travel, in the DBC's unit
    "brake_pressed": ("", Interp.PREVIOUS, False),  # switch, 0/1
    "time_base": ("s", Interp.LINEAR, False),  # ECU timer or counter in the motor speed's message
    "accel_long_ms2": ("m/s^2", Interp.LINEAR, False),  # longitudinal acceleration (ESP/ABS or IMU), + forward
}
TIME_BASE = "time_base"
REQUIRED: tuple[str, ...] = tuple(k for k, (_, _, req) in CANONICAL.items() if req)

G_N = 9.80665  # standard gravity, m/s^2 per g
#: canonical unit -> {accepted spelling (normalised) -> factor to the canonical unit}
UNIT_FACTORS: dict[str, dict[str, float]] = {
    "rpm": {"rpm": 1.0, "1/min": 1.0, "u/min": 1.0, "rev/min": 1.0, "r/min": 1.0, "min-1": 1.0, "min^-1": 1.0,
            "rad/s": RPM_PER_RAD_S, "rads/s": RPM_PER_RAD_S,
            "rad/sec": RPM_PER_RAD_S, "rps": 60.0, "rev/s": 60.0, "deg/s": 1.0 / 6.0, "krpm": 1000.0},
    "Nm": {"nm": 1.0, "n.m": 1.0, "n*m": 1.0, "n-m": 1.0, "n·m": 1.0, "newtonmeter": 1.0, "knm": 1000.0, "dnm": 0.1},
    "km/h": {"km/h": 1.0, "kph": 1.0, "kmh": 1.0, "kmph": 1.0, "m/s": 3.6, "mph": 1.609344},
    "%": {"%": 1.0, "pct": 1.0, "percent": 1.0},
    "s": {"s": 1.0, "sec": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6},
    "m/s^2": {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "m/s/s": 1.0, "m/s**2": 1.0, "mps2": 1.0, "mps^2": 1.0,
              "g": G_N, "gn": G_N, "mg": 1e-3 * G_N},
}


def normalise_unit(unit: str | None) -> str:
    """Lower case, no spaces, without a quantity prefix: ``"torque:N.m"`` -> ``"n.m"``.

    Some inverter vendors' DBCs write units as ``quantity:unit`` (``angular_speed:rpm``,
    ``current:A``); the quantity is dropped so the unit converts like any other.
    """
    text = "".join((unit or "").split()).lower()
    quantity, sep, rest = text.partition(":")
    return rest if sep and rest and quantity.replace("_", "").isalpha() else text


def unit_factor(from_unit: str | None, canonical: str) -> float | None:
    """Factor from ``from_unit`` to ``canonical``; 1 for an empty unit; None when not convertible."""
    norm = normalise_unit(from_unit)
    if not norm or not canonical or norm == normalise_unit(canonical):
        return 1.0
    return UNIT_FACTORS.get(canonical, {}).get(norm)


@dataclass(frozen=True, slots=True)
class ChannelSpec:
    """One ``[channels.<name>]`` table of a map."""

    channel: str
    message: str | int  # name, or frame ID
    signal: str
    unit: str | None = None
    factor: float = 1.0
    offset: float = 0.0
    invert: bool = False
    bus: int | None = None


@dataclass(frozen=True, slots=True)
class ResolvedChannel:
    """A channel checked against a database: the message and signal, and the final linear conversion."""

    spec: ChannelSpec
    message: Message
    signal: CanSignal
    gain: float  # out = gain * value + offset
    offset: float
    unit: str
    interp: Interp


@dataclass(slots=True)
class SignalMap:
    """Canonical channels of one vehicle and where each comes from."""

    name: str
    channels: dict[str, ChannelSpec]
    source: Path | None = None
    notes: list[str] = field(default_factory=list)

    def where(self) -> str:
        return f"signal map {self.source}" if self.source else f"signal map {self.name!r}"

    def resolve(self, db: CanDatabase) -> dict[str, ResolvedChannel]:
        """Check every channel against ``db`` and work out its conversion.

        Raises
        ------
        SignalMapError
            Naming the channel, message and signal that do not fit, or the unit that cannot convert.
        """
        out: dict[str, ResolvedChannel] = {}
        for name, spec in self.channels.items():
            canonical_unit, interp, _ = CANONICAL[name]
            msg = _find_message(db, spec.message)
            if msg is None:
                raise SignalMapError(f"{self.where()}: channel {name}: message {spec.message!r} is not in the database")
            try:
                sig = msg.get_signal_by_name(spec.signal)
            except KeyError:
                raise SignalMapError(
                    f"{self.where()}: channel {name}: message {msg.name} has no signal {spec.signal!r}"
                ) from None
            src_unit = spec.unit if spec.unit is not None else (sig.unit or "")
            factor = unit_factor(src_unit, canonical_unit)
            if factor is None:
                raise SignalMapError(
                    f"{self.where()}: channel {name}: cannot convert unit {src_unit!r} of {msg.name}.{sig.name} "
                    f"to {canonical_unit!r}; set unit = {canonical_unit!r} and a factor"
                )
            gain = factor * spec.factor * (-1.0 if spec.invert else 1.0)
            unit = canonical_unit or src_unit
            out[name] = ResolvedChannel(spec, msg, sig, gain, spec.offset, unit, interp)
        speed = out.get("motor_speed_rpm")
        timer = out.get(TIME_BASE)
        if timer is not None and (speed is None or speed.message.frame_id != timer.message.frame_id
                                  or speed.spec.bus != timer.spec.bus):
            raise SignalMapError(
                f"{self.where()}: channel {TIME_BASE}: {timer.message.name}.{timer.signal.name} must be a signal of "
                f"the motor speed's message ({speed.message.name if speed else 'motor_speed_rpm is not mapped'}): "
                "its value times each speed sample")
        return out

    def routes(self, db: CanDatabase) -> dict[str, tuple[str, str]]:
        """Channel -> (message name, signal name), validated against ``db``."""
        return {k: (r.message.name, r.signal.name) for k, r in self.resolve(db).items()}

    def to_toml(self) -> str:
        """The map as TOML text (round-trips through :func:`parse_signal_map`)."""
        lines = ["[vehicle]", f"name = {_q(self.name)}", ""]
        for name, spec in self.channels.items():
            lines.append(f"[channels.{name}]")
            msg = spec.message if isinstance(spec.message, str) else f"0x{spec.message:X}"
            lines += [f"message = {_q(msg)}", f"signal = {_q(spec.signal)}"]
            if spec.unit is not None:
                lines.append(f"unit = {_q(spec.unit)}")
            if spec.factor != 1.0:
                lines.append(f"factor = {spec.factor!r}")
            if spec.offset != 0.0:
                lines.append(f"offset = {spec.offset!r}")
            if spec.invert:
                lines.append("invert = true")
            if spec.bus is not None:
                lines.append(f"bus = {spec.bus}")
            lines.append("")
        return "\n".join(lines)


def _q(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _find_message(db: CanDatabase, ref: str | int) -> Message | None:
    if isinstance(ref, str):
        try:
            return db.get_message_by_name(ref)
        except KeyError:
            try:
                ref = int(ref, 0)
            except ValueError:
                return None
    for msg in db.messages:
        if msg.frame_id == ref:
            return msg
    return None


_KEYS = {"message", "signal", "unit", "factor", "offset", "invert", "bus"}


def parse_signal_map(data: Mapping[str, Any], where: str = "signal map") -> SignalMap:
    """Build a :class:`SignalMap` from parsed TOML, naming the channel and key of every problem."""
    vehicle = data.get("vehicle", {})
    if not isinstance(vehicle, Mapping):
        raise SignalMapError(f"{where}: [vehicle] must be a table")
    channels = data.get("channels")
    if not isinstance(channels, Mapping) or not channels:
        raise SignalMapError(f"{where}: no [channels.<name>] tables; canonical channels are {', '.join(CANONICAL)}")
    unknown_top = set(data) - {"vehicle", "channels"}
    if unknown_top:
        raise SignalMapError(f"{where}: unknown top-level keys {sorted(unknown_top)}; expected [vehicle], [channels.*]")
    specs: dict[str, ChannelSpec] = {}
    for name, table in channels.items():
        if name not in CANONICAL:
            raise SignalMapError(f"{where}: unknown channel {name!r}; canonical channels are {', '.join(CANONICAL)}")
        if not isinstance(table, Mapping):
            raise SignalMapError(f"{where}: channel {name} must be a table")
        extra = set(table) - _KEYS
        if extra:
            raise SignalMapError(f"{where}: channel {name}: unknown keys {sorted(extra)}; allowed {sorted(_KEYS)}")
        specs[name] = _spec(name, table, where)
    return SignalMap(str(vehicle.get("name", "")), specs)


def _spec(name: str, t: Mapping[str, Any], where: str) -> ChannelSpec:
    def need(key: str, types: tuple[type, ...]) -> Any:
        value = t.get(key)
        if value is None:
            raise SignalMapError(f"{where}: channel {name}: missing {key!r}")
        if not isinstance(value, types) or isinstance(value, bool):
            raise SignalMapError(f"{where}: channel {name}: {key} = {value!r} has the wrong type")
        return value

    def opt(key: str, types: tuple[type, ...], default: Any) -> Any:
        value = t.get(key, default)
        ok = isinstance(value, types) and (bool in types or not isinstance(value, bool))
        if value is not default and not ok:
            raise SignalMapError(f"{where}: channel {name}: {key} = {value!r} has the wrong type")
        return value

    factor = float(opt("factor", (int, float), 1.0))
    offset = float(opt("offset", (int, float), 0.0))
    if not (math.isfinite(factor) and math.isfinite(offset)) or factor == 0.0:
        raise SignalMapError(f"{where}: channel {name}: factor {factor}, offset {offset} must be finite, factor != 0")
    bus = opt("bus", (int,), None)
    if bus is not None and bus < 0:
        raise SignalMapError(f"{where}: channel {name}: bus = {bus} must be >= 0")
    return ChannelSpec(name, need("message", (str, int)), need("signal", (str,)), opt("unit", (str,), None),
                       factor, offset, bool(opt("invert", (bool,), False)), bus)


def load_signal_map(path: str | Path) -> SignalMap:
    """Read a signal map TOML file.

    Raises
    ------
    SignalMapError
        Unreadable file, TOML syntax error (with line), unknown channel or key, wrong type.
    """
    src = Path(path)
    try:
        text = src.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise SignalMapError(f"signal map {src}: cannot read ({exc})") from exc
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SignalMapError(f"signal map {src}: invalid TOML: {exc}") from exc
    smap = parse_signal_map(data, f"signal map {src}")
    smap.source = src
    return smap
