"""A signal map proposed from a log and its DBC, with the evidence for each channel.

:mod:`app.ingest.suggest` ranks a database's signals by name, unit and message rate; this module
reads the log once for its message rates, takes the best candidates, decodes them, and adds what
the data itself says about each channel:

- **rate**: samples per second in the log (and the message's frame count);
- **unit**: the DBC's unit and the factor to the canonical one;
- **range**: the decoded extremes in the canonical unit;
- **correlation**: motor torque and motor speed against each other (rank correlation of the torque
  with the motor acceleration, :func:`app.analysis.logchecks.sign_correlation`: positive when the
  two agree), the pedal against the torque, road and wheel speeds against the motor speed;
- **sign**: a motor speed that is mostly negative while the car moves is proposed inverted, then a
  torque whose correlation with the acceleration is clearly negative is proposed inverted.

The user's own choices (``role=Message.Signal``) replace the proposal channel by channel before
the evidence is taken, so the evidence is always that of the map that will be stored.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from app.analysis.logchecks import CheckParams, sign_correlation
from app.analysis.series import finite_signal
from app.errors import InputError, SignalMapError
from app.ingest.database import LoadedDatabase, load_database
from app.ingest.pipeline_signals import load_signals
from app.ingest.readers import open_log
from app.ingest.signalmap import CANONICAL, REQUIRED, TIME_BASE, ChannelSpec, SignalMap, unit_factor
from app.ingest.stats import DecodeReport, StatsAccumulator
from app.ingest.suggest import Candidate, observed, suggest_candidates, suggest_signal_map
from app.serial import Serial, rule
from app.signals import Signal, SignalSet

MIN_SIGN_CORRELATION = 0.3  # as app.analysis.logchecks.CheckParams: below -this the torque is proposed inverted
MOVING_RPM = 100.0  # motor speed samples beyond this (either way) say which way the motor turns


@dataclass(frozen=True)
class ChannelEvidence(Serial):
    """What the log says about one proposed channel."""

    channel: str
    source: str  # "Message.Signal"
    dbc_unit: str
    unit: str  # canonical
    factor: float  # DBC unit -> canonical unit
    invert: bool
    chosen_by: str  # "suggested" or "user"
    score: float | None  # the name/unit/rate score of app.ingest.suggest (None: the user's choice, not ranked)
    reasons: tuple[str, ...]
    samples: int
    rate_hz: float | None
    minimum: float | None
    maximum: float | None
    correlation: float | None  # see correlation_with
    correlation_with: str  # what the correlation is taken against, in words
    sign: str  # the sign check in words


@dataclass
class Proposal(Serial):
    """The proposed map, its evidence per channel, and the other candidates per channel."""

    smap: SignalMap = field(metadata=rule(key="signal_map_toml", convert=SignalMap.to_toml))
    evidence: dict[str, ChannelEvidence] = field(metadata=rule(key="channels", convert=lambda ev: list(ev.values())))
    candidates: dict[str, list[Candidate]] = field(metadata=rule(convert=lambda cs: {
        ch: [f"{c.message}.{c.signal}" for c in cands] for ch, cands in cs.items()}))
    database: str
    log_format: str
    frames: int
    duration_s: float
    missing: list[str] = field(default_factory=list)  # required channels with no signal

    serial_order = ("database", "log_format", "frames", "duration_s", "missing", "evidence", "candidates", "smap")


def parse_overrides(items: list[str] | tuple[str, ...]) -> dict[str, str | None]:
    """``role=Message.Signal`` items (``role=`` or ``role=-`` drops the channel) -> {role: "Message.Signal" | None}.

    Raises InputError (code ``invalid_map_override``) naming the item.
    """
    out: dict[str, str | None] = {}
    for item in items:
        role, sep, source = (s.strip() for s in item.partition("="))
        if not sep or role not in CANONICAL:
            raise InputError(f"--map {item!r}: expected ROLE=Message.Signal with ROLE one of {', '.join(CANONICAL)}",
                             code="invalid_map_override")
        if source in ("", "-"):
            out[role] = None
            continue
        message, dot, signal = source.partition(".")
        if not dot or not message or not signal:
            raise InputError(f"--map {item!r}: expected ROLE=Message.Signal (the DBC's message and signal names)",
                             code="invalid_map_override")
        out[role] = source
    return out


def check_source(db: LoadedDatabase, role: str, source: str) -> ChannelSpec:
    """A channel spec for ``Message.Signal``, checked against the database (names the near misses)."""
    message, _, signal = source.partition(".")
    try:
        msg = db.db.get_message_by_name(message)
    except KeyError:
        raise SignalMapError(f"{role}={source}: the database has no message {message!r}") from None
    names = [s.name for s in msg.signals]
    if signal not in names:
        raise SignalMapError(f"{role}={source}: message {message} has no signal {signal!r}; it has {', '.join(names)}")
    return ChannelSpec(role, message, signal)


def _scan(log: Path, loaded: LoadedDatabase, strict: bool) -> tuple[dict[int, float], dict[int, int], str, int, float]:
    """Observed mean periods and frame counts per frame ID, the format, frames and duration (no decoding)."""
    stats = StatsAccumulator(loaded.db)
    with open_log(log, strict=strict) as reader:
        for chunk in reader.chunks():
            stats.add_chunk(chunk)
        report = stats.fill(DecodeReport(source=str(log), format=reader.meta.format, database=loaded.name))
    periods, counts = observed(report.ids)
    return periods, counts, report.format, report.frames_read, report.duration_s


def propose(log: Path, database: Path, overrides: Mapping[str, str | None] | None = None, *,
            invert: Mapping[str, bool] | None = None, strict: bool = False) -> Proposal:
    """The proposed signal map for ``log`` decoded with ``database``, and its evidence.

    ``overrides`` replace or drop channels (:func:`parse_overrides`); ``invert`` fixes a channel's sign
    (otherwise the sign checks propose it). Raises the readers' and the database's errors, and
    SignalMapError for an override the database does not have.
    """
    loaded = load_database(database, tolerant=not strict)
    periods, counts, fmt, frames, duration = _scan(log, loaded, strict)
    candidates = suggest_candidates(loaded.db, periods, limit=3, counts=counts)
    draft = suggest_signal_map(loaded.db, periods, counts=counts)
    channels = dict(draft.channels)
    chosen = {ch: "suggested" for ch in channels}
    for role, source in (overrides or {}).items():
        if source is None:
            channels.pop(role, None)
            chosen.pop(role, None)
        else:
            channels[role] = check_source(loaded, role, source)
            chosen[role] = "user"
    if "motor_speed_rpm" not in channels:
        channels.pop(TIME_BASE, None)  # a time base times the speed's own message
    # canonical order, so the stored file reads the same every time
    channels = {ch: channels[ch] for ch in CANONICAL if ch in channels}
    smap = SignalMap("proposed", channels, notes=["proposed from the log and the DBC by lashscope init"])
    evidence: dict[str, ChannelEvidence] = {}
    if channels:
        signals, _ = load_signals(log, loaded, smap, strict=strict)
        flips = _sign_choices(signals, invert or {})
        if any(flips.values()):
            smap = SignalMap(smap.name, {ch: replace(s, invert=flips.get(ch, False)) for ch, s in channels.items()},
                             notes=smap.notes)
            signals = SignalSet({name: _flipped(s, flips.get(name, False)) for name, s in signals.items()})
        by_source = {(c.channel, c.message, c.signal): c for cands in candidates.values() for c in cands}
        for ch, spec in smap.channels.items():
            evidence[ch] = _evidence(loaded, ch, spec, signals, chosen[ch], by_source, counts)
    missing = [c for c in REQUIRED if c not in smap.channels]
    return Proposal(smap, evidence, candidates, loaded.name, fmt, frames, duration, missing)


def _sign_choices(signals: SignalSet, fixed: Mapping[str, bool]) -> dict[str, bool]:
    """Which of motor speed and torque to invert: the user's choice, else the sign checks."""
    out = dict(fixed)
    speed = signals.get("motor_speed_rpm")
    if "motor_speed_rpm" not in out and speed is not None:
        moving = speed.values[np.abs(np.nan_to_num(speed.values)) > MOVING_RPM]
        out["motor_speed_rpm"] = bool(moving.size and np.median(moving) < 0)
    torque = signals.get("motor_torque_nm")
    if "motor_torque_nm" not in out and torque is not None and speed is not None:
        corr = _torque_correlation(torque, _flipped(speed, out.get("motor_speed_rpm", False)))
        out["motor_torque_nm"] = bool(np.isfinite(corr) and corr < -MIN_SIGN_CORRELATION)
    return out


def _flipped(s: Signal, flip: bool) -> Signal:
    return replace(s, values=-s.values) if flip else s


def _torque_correlation(torque: Signal, speed: Signal) -> float:
    if len(torque) < 2 or len(speed) < 2:
        return float("nan")
    return sign_correlation(finite_signal(torque), finite_signal(speed), CheckParams().accel_window_s)


def _pearson(a: Signal, b: Signal) -> float:
    """Correlation of ``a`` with ``b`` at ``a``'s sample times (NaN when too few or constant)."""
    if len(a) < 20 or len(b) < 2:
        return float("nan")
    x, y = a.values, b.at(a.t)
    ok = np.isfinite(x) & np.isfinite(y)
    if ok.sum() < 20 or np.ptp(x[ok]) == 0 or np.ptp(y[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(x[ok], y[ok])[0, 1])


def _evidence(loaded: LoadedDatabase, ch: str, spec: ChannelSpec, signals: SignalSet, chosen_by: str,
              by_source: Mapping[tuple[str, str, str], Candidate], counts: Mapping[int, int]) -> ChannelEvidence:
    msg = loaded.db.get_message_by_name(str(spec.message)) if isinstance(spec.message, str) else None
    sig = msg.get_signal_by_name(spec.signal) if msg is not None else None
    dbc_unit = (sig.unit or "") if sig is not None else ""
    canonical = CANONICAL[ch][0]
    factor = unit_factor(spec.unit if spec.unit is not None else dbc_unit, canonical) or 1.0
    s = signals.get(ch)
    n = len(s) if s is not None else 0
    vals = s.values[np.isfinite(s.values)] if s is not None else np.zeros(0)
    span = float(s.t[-1] - s.t[0]) if n > 1 and s is not None else 0.0
    rate = (n - 1) / span if span > 0 else None
    cand = by_source.get((ch, str(spec.message), spec.signal))
    corr, against, sign = _check(ch, spec, signals)
    return ChannelEvidence(
        channel=ch, source=f"{spec.message}.{spec.signal}", dbc_unit=dbc_unit, unit=canonical or dbc_unit,
        factor=factor, invert=spec.invert, chosen_by=chosen_by, score=cand.score if cand else None,
        reasons=cand.reasons if cand else (), samples=n, rate_hz=rate,
        minimum=float(vals.min()) if vals.size else None, maximum=float(vals.max()) if vals.size else None,
        correlation=corr, correlation_with=against, sign=sign)


def _check(ch: str, spec: ChannelSpec, signals: SignalSet) -> tuple[float | None, str, str]:
    """(correlation or None, what against, the sign check in words) for one channel."""
    speed, torque = signals.get("motor_speed_rpm"), signals.get("motor_torque_nm")
    inverted = " (after inverting)" if spec.invert else ""

    def num(v: float) -> float | None:
        return v if np.isfinite(v) else None

    if ch in ("motor_torque_nm", "motor_speed_rpm"):
        if speed is None or torque is None:
            return None, "", "not checked: needs both motor torque and motor speed"
        corr = num(_torque_correlation(torque, speed))
        against = "torque vs motor acceleration (rank)"
        if corr is None:
            return None, against, "not checked: too few samples or a constant channel"
        if ch == "motor_speed_rpm":
            moving = speed.values[np.abs(np.nan_to_num(speed.values)) > MOVING_RPM]
            share = float(np.mean(moving > 0)) if moving.size else float("nan")
            where = f"positive in {100 * share:.0f} % of the samples beyond {MOVING_RPM:g} rpm" if moving.size \
                else f"never beyond {MOVING_RPM:g} rpm"
            return corr, against, f"{where}{inverted}"
        verdict = "agrees with the speed" if corr > MIN_SIGN_CORRELATION else (
            "opposes the speed" if corr < -MIN_SIGN_CORRELATION else "undecided (weak correlation)")
        return corr, against, f"{verdict}{inverted}"
    if ch == "pedal_pct" and torque is not None and ch in signals:
        corr = num(_pearson(signals[ch], torque))
        ok = "" if corr is None else (" rises with the torque" if corr > 0 else " falls as the torque rises: check it")
        return corr, "pedal vs motor torque", ok.strip() or "not checked"
    if (ch == "vehicle_speed_kmh" or ch.startswith("wheel_speed_")) and speed is not None and ch in signals:
        corr = num(_pearson(signals[ch], speed))
        ok = "" if corr is None else ("follows the motor speed" if corr > 0.5 else "does not follow the motor speed")
        return corr, f"{ch} vs motor speed", ok or "not checked"
    return None, "", "-"


def proposal_table(p: Proposal) -> str:
    """The proposal as text: one row per channel with its evidence, then the alternatives."""

    def num(v: float | None, fmt: str) -> str:
        return "-" if v is None else format(v, fmt)

    lines = [f"log: {p.log_format}, {p.frames} frames over {p.duration_s:.1f} s; database {p.database}",
             f"{'channel':<20} {'source (Message.Signal)':<34} {'unit':<12} {'rate (Hz)':>9} "
             f"{'range (canonical unit)':>24} {'corr':>6}  sign / correlation with"]
    for e in p.evidence.values():
        unit = f"{e.dbc_unit or '-'}" + (f" x{e.factor:.4g}" if e.factor != 1.0 else "")
        rng = f"{num(e.minimum, '.1f')}..{num(e.maximum, '.1f')} {e.unit}"
        who = "" if e.chosen_by == "suggested" else " (yours)"
        inv = " inverted" if e.invert else ""
        lines.append(f"{e.channel:<20} {e.source + who:<34} {unit:<12} {num(e.rate_hz, '.1f'):>9} {rng:>24} "
                     f"{num(e.correlation, '+.2f'):>6}  {e.sign}{inv}"
                     + (f"; {e.correlation_with}" if e.correlation_with else ""))
    for ch, cands in p.candidates.items():
        used = p.smap.channels.get(ch)
        others = [f"{c.message}.{c.signal}" for c in cands
                  if used is None or (c.message, c.signal) != (used.message, used.signal)]
        if others and (used is not None or ch in REQUIRED):
            lines.append(f"  other candidates for {ch}: {', '.join(others)}")
    if p.missing:
        lines.append(f"missing (every analysis needs them): {', '.join(p.missing)}; give --map ROLE=Message.Signal")
    return "\n".join(lines)
