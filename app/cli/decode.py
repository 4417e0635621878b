"""``lashscope decode LOG --dbc DBC [--map MAP] [--out DIR] [--format parquet,csv] [--strict]``.

With a signal map the canonical channels are written as one long table (``signals.parquet``
/ ``signals.csv``: channel, t_s, value, unit). Without one every database message is decoded
into its own wide table under ``messages/`` (t_s, bus, one column per signal) and signal-map
candidates are printed. Either way the decode report is printed: frames read, per-ID counts
and periods with jitter, decode errors, counter gaps, timestamp anomalies, and every skipped or
corrupt region of the log with its byte offset or line number.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.cli.log_args import add_format_file, log_help
from app.errors import InputError, StorageError

if TYPE_CHECKING:  # the command imports numpy, cantools and pyarrow when it runs, not when --help is built
    from app.ingest.database import LoadedDatabase
    from app.ingest.stats import CounterGaps, DecodeReport
    from app.ingest.tables import MessageTables
    from app.signals.signal import SignalSet

FORMATS = ("parquet", "csv")  # the same as app.ingest.tables.FORMATS (not imported here: it needs numpy)


def register(subparsers: Any) -> None:
    p = subparsers.add_parser("decode", help="decode a CAN log with a DBC (and signal map); print the bus report",
                              description=__doc__.split("\n\n", 1)[1] if __doc__ else None)
    p.add_argument("log", type=Path, help=log_help())
    add_format_file(p)
    p.add_argument("--dbc", type=Path, required=True, help="DBC, KCD, SYM or ARXML database")
    p.add_argument("--map", type=Path, default=None, help="signal map TOML (canonical channels)")
    p.add_argument("--out", type=Path, default=None, help="write decoded tables to this folder")
    p.add_argument("--format", default="parquet,csv", help="comma-separated: parquet, csv (default both)")
    p.add_argument("--strict", action="store_true",
                   help="no DBC repairs and stop at the first damaged log record")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.ingest.database import load_database
    from app.ingest.pipeline_signals import load_signals
    from app.ingest.signalmap import load_signal_map
    from app.ingest.tables import MessageTables

    formats = [f.strip().lower() for f in str(args.format).split(",") if f.strip()]
    bad = [f for f in formats if f not in FORMATS]
    if bad or not formats:
        raise InputError(f"--format {args.format!r}: choose from {', '.join(FORMATS)}")
    loaded = load_database(args.dbc, tolerant=not args.strict)
    if args.map is not None:
        smap = load_signal_map(args.map)
        signals, report = load_signals(args.log, loaded, smap, strict=args.strict)
        print(format_report(report))
        print(format_channels(signals))
        if args.out is not None:
            for path in write_signals(signals, args.out, formats):
                print(f"wrote {path}")
        return 0
    tables = MessageTables(args.out / "messages", formats) if args.out is not None else None
    report = decode_log(args.log, loaded, strict=args.strict, tables=tables)
    print(format_report(report))
    print(format_suggestions(loaded, report))
    for path in tables.paths if tables is not None else []:
        print(f"wrote {path}")
    return 0


def decode_log(log: Path, loaded: LoadedDatabase, *, strict: bool = False, tables: MessageTables | None = None,
               chunk_frames: int = 65536) -> DecodeReport:
    """Decode every message of the database chunk by chunk; the report (and the tables, streamed).

    Nothing decoded is kept beyond the current chunk, except what ``tables`` buffers within its
    memory budget; ``tables`` is closed (its files complete) when this returns or raises.
    """
    from app.ingest.decode import VectorDecoder
    from app.ingest.readers import open_log
    from app.ingest.stats import DecodeReport, StatsAccumulator

    decoder = VectorDecoder(loaded.db)
    stats = StatsAccumulator(loaded.db)
    try:
        with open_log(log, strict=strict, chunk_frames=chunk_frames) as reader:
            for chunk in reader.chunks():
                decoded = stats.add(chunk, decoder)
                if tables is not None:
                    tables.add(decoded)
            report = DecodeReport(source=str(log), format=reader.meta.format, database=loaded.name,
                                  database_repairs=list(loaded.repairs), database_notes=list(loaded.notes),
                                  reader_issues=list(reader.report.issues))
    finally:
        if tables is not None:
            tables.close()
    return stats.fill(report)


def _write(table: Any, base: Path, formats: Iterable[str]) -> list[Path]:
    import pyarrow.csv as pacsv
    import pyarrow.parquet as pq

    written = []
    try:
        base.parent.mkdir(parents=True, exist_ok=True)
        for fmt in formats:
            path = base.with_suffix(f".{fmt}")
            if fmt == "parquet":
                pq.write_table(table, path)
            else:
                pacsv.write_csv(table, path)
            written.append(path)
    except OSError as exc:
        raise StorageError(f"cannot write decoded data to {base.parent}: {exc.strerror or exc}") from exc
    return written


def write_signals(signals: SignalSet, out: Path, formats: Iterable[str]) -> list[Path]:
    """Canonical channels as one long table ``signals.<fmt>`` (channel, t_s, value, unit)."""
    import numpy as np

    from app.ingest import arrow

    names = list(signals)
    lengths = [len(signals[n]) for n in names]
    units = sorted({signals[n].unit for n in names})
    # dictionary columns built from per-sample indices: no Python string per sample
    rows = np.repeat(np.arange(len(names), dtype=np.int32), lengths)
    unit_of = np.array([units.index(signals[n].unit) for n in names], np.int32)
    table = arrow.table({
        "channel": arrow.categories(rows, names),
        "t_s": np.concatenate([signals[n].t for n in names]) if names else np.empty(0),
        "value": np.concatenate([signals[n].values for n in names]) if names else np.empty(0),
        "unit": arrow.categories(unit_of[rows], units),
    })
    return _write(table, out / "signals", formats)


def _ms(value: float | None) -> str:
    return "-" if value is None else f"{value:.3f}"


def format_report(r: DecodeReport) -> str:
    """The decode report as text for a terminal."""
    lines = [f"log {r.source} ({r.format}), database {r.database}",
             f"frames read {r.frames_read}, decoded {r.frames_decoded}, unknown ID {r.frames_unknown_id}, "
             f"error frames {r.error_frames}, remote frames {r.remote_frames}, duration {r.duration_s:.3f} s"]
    if r.unknown_hint:
        lines.append(f"  why unknown: {r.unknown_hint}")
    for rep in r.database_repairs:
        lines.append(f"  database repair line {rep.line if rep.line is not None else '?'}: {rep.kind}: {rep.message}")
    lines += [f"  database note: {note.kind}: {note.message}" for note in r.database_notes]
    lines += ["", "per ID (bus, ID, message): count, period ms (mean), jitter ms (std), min/max gap ms, "
              "median/p95 gap ms, DBC cycle ms; * = bursty"]
    for s in r.ids:
        ident = f"0x{s.arb_id:08X}x" if s.extended else f"0x{s.arb_id:03X}"
        lines.append(f"  {s.channel:>3} {ident:<12} {s.message or '?':<28} {s.count:>9} {_ms(s.period_ms):>10} "
                     f"{_ms(s.jitter_ms):>9} {_ms(s.min_gap_ms):>9}/{_ms(s.max_gap_ms):<9} "
                     f"{_ms(s.median_gap_ms):>9}/{_ms(s.p95_gap_ms):<9} "
                     f"{'-' if s.cycle_ms is None else f'{s.cycle_ms:g}'}{' *' if s.bursty else ''}")
    bursty = [s for s in r.ids if s.bursty and s.message]
    if bursty:
        lines.append("bursty or gapped messages (take their period from the mean, not the median):")
        lines += [f"  {s.message}: {s.bursty_reason}" for s in bursty]
    for name, n in sorted(r.id_type_mismatch.items()):
        lines.append(f"  {n} frames carry the ID of {name} with the other ID type (11/29 bit): not decoded")
    lines += ["", "decode errors:" if r.decode_errors else "decode errors: none"]
    for name, kinds in sorted(r.decode_errors.items()):
        lines.append(f"  {name}: " + ", ".join(f"{k} {v}" for k, v in sorted(kinds.items())))
    lines.append("counter gaps:" if r.counter_gaps else "counter gaps: no alive counters decoded")
    for g in r.counter_gaps:
        lines.append(f"  bus {g.channel} {g.message}.{g.signal} ({g.frames} frames): {format_counter(g)}")
    lines += _timestamp_lines(r)
    # Backwards steps are a property of the timestamps (above), not a region the reader skipped.
    regions = [i for i in r.reader_issues if i.kind != "time_backwards"]
    lines.append("skipped or corrupt regions:" if regions else "skipped or corrupt regions: none")
    for i in regions:
        where = f"byte {i.offset}" if i.offset is not None else (f"line {i.line}" if i.line is not None else "-")
        lost = f", {i.frames_lost} frames lost" if i.frames_lost else ""
        lost += f", {i.bytes_lost} bytes" if i.bytes_lost else ""
        times = f" (x{i.count})" if i.count > 1 else ""
        lines.append(f"  {where}: {i.kind}{times}: {i.message}{lost}")
    return "\n".join(lines)


def _timestamp_lines(r: DecodeReport) -> list[str]:
    """Timestamp anomalies per bus, then backwards steps in file order explained against them.

    The reader counts time going backwards in file order across all buses; the statistics count it
    per bus. A multi-bus logger (GVRET/SavvyCAN) that interleaves buses steps back in file order
    while each bus's own time runs forward, which is no damage.
    """
    counts = ", ".join(f"{k} {v}" for k, v in sorted(r.anomaly_counts.items())) or "none"
    lines = ["timestamp anomalies:", f"  per bus: {counts}"]
    for a in r.timestamp_anomalies:
        lines.append(f"    {a.kind}: bus {a.channel} frame {a.frame} at {a.t_s:.6f} s (step {a.dt_s:+.6f} s)")
    n_file = sum(i.count for i in r.reader_issues if i.kind == "time_backwards")
    if not n_file:
        lines.append("  in file order (all buses): none")
        return lines
    first = next(i for i in r.reader_issues if i.kind == "time_backwards")
    where = first.message.partition("(")[2].partition(")")[0]  # "first before frame index N"
    per_bus = r.anomaly_counts.get("backwards", 0)
    multi_bus = len({s.channel for s in r.ids}) > 1
    text = f"  in file order (all buses): {n_file} backward steps" + (f" ({where})" if where else "")
    if per_bus == 0 and multi_bus:
        text += ("; none within a bus: the buses are logged interleaved and each bus's own time runs forward "
                 "(no frame skipped; frames kept in logged order)")
    elif per_bus and multi_bus:
        text += (f"; {per_bus} within a bus (above), the others where interleaved buses meet "
                 "(no frame skipped; frames kept in logged order)")
    else:
        text += "; the per-bus steps above (no frame skipped; frames kept in logged order)"
    lines.append(text)
    return lines


def format_counter(g: CounterGaps) -> str:
    """One counter's pattern and deviations, e.g. ``step +1 mod 15 (fits 99.8%): 1 gaps, 3 frames missed, ...``."""
    if g.kind == "constant":
        text = f"{g.pattern} (not counting in this log)"
    elif g.kind in ("irregular", "unknown"):
        text = "no counting pattern fits: not checked" if g.kind == "irregular" else "too few frames to check"
    else:
        text = (f"{g.pattern} (fits {100 * (g.fit or 0.0):.1f}%): {g.gaps} gaps, {g.missed} frames missed, "
                f"{g.repeats} repeats" + (f", first gap at {g.first_gap_s:.3f} s" if g.first_gap_s is not None else ""))
    if g.pattern_changes:
        text += f"; pattern changed {g.pattern_changes} times"
    if g.unchecked and g.kind != "irregular":
        text += f"; {g.unchecked} steps fit no pattern (not checked)"
    return text


def format_channels(signals: SignalSet) -> str:
    import numpy as np

    from app.signals.sampling import spacing

    lines = ["", "canonical channels: samples, span s, NaN (not available), unit; spacing ms mean/median/p95/max"]
    notes = []
    for name, s in signals.items():
        span = f"{s.t[0]:.3f}..{s.t[-1]:.3f}" if len(s) else "-"
        sp = spacing(s.t)
        lines.append(f"  {name:<20} {len(s):>9} {span:>20} {int(np.isnan(s.values).sum()):>7} {s.unit:<5} "
                     f"{_ms(sp.mean_ms)}/{_ms(sp.median_ms)}/{_ms(sp.p95_ms)}/{_ms(sp.max_ms)}"
                     + (" bursty" if sp.bursty else ""))
        if sp.bursty:
            notes.append(f"  {name}: {sp.reason}")
    return "\n".join(lines + notes)


def format_suggestions(loaded: LoadedDatabase, report: DecodeReport) -> str:
    """Candidates per channel and a draft map, from the messages the log carries."""
    from app.ingest.suggest import MIN_FRAMES, observed, suggest_candidates, suggest_signal_map

    periods, counts = observed(report.ids)
    lines = ["", f"no --map given; signal map candidates from messages with >= {MIN_FRAMES} frames in the log "
             "(score: reasons):"]
    for channel, cands in suggest_candidates(loaded.db, periods, limit=3, counts=counts).items():
        lines.append(f"  {channel}:" + ("" if cands else " no candidate"))
        for c in cands:
            lines.append(f"    {c.message}.{c.signal} [{c.unit}] {c.score:g}: {'; '.join(c.reasons)}")
    draft = suggest_signal_map(loaded.db, periods, counts=counts).to_toml()
    lines += ["", "draft map (check signs, units and scale before use):", draft]
    return "\n".join(lines)

