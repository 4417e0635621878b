"""``lashscope replay LOG --interface I --channel C [--rate R] [--loop] [--ids ...]``.

Sends the frames of a log onto a CAN bus with their original timing (scaled by ``--rate``),
shows progress, and on Ctrl-C (SIGINT) or SIGTERM stops cleanly and prints a summary (exit
code 130 or 143). Every argument is checked before the bus is opened.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
from collections.abc import Callable, Generator
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

from app.cli.log_args import add_format_file, log_help
from app.errors import InputError

if TYPE_CHECKING:  # python-can and numpy are imported when the command runs, not when --help is built
    from app.ingest.frames import FrameChunk
    from app.live.bus import BusConfig
    from app.live.replay import ReplayStats

# For the help text only (listing python-can's interfaces would import python-can); an unknown
# name is refused with the full list when the bus is opened.
INTERFACE_EXAMPLES = "socketcan, pcan, vector, kvaser, virtual, tcp_loopback, ..."


def parse_options(pairs: list[str] | None) -> dict[str, object]:
    """``["fd=true", "data_bitrate=2000000"]`` -> python-can keyword arguments."""
    out: dict[str, object] = {}
    for pair in pairs or []:
        key, sep, raw = pair.partition("=")
        if not sep or not key:
            raise InputError(f"--option {pair!r}: write KEY=VALUE")
        low = raw.lower()
        value: object
        if low in ("true", "false"):
            value = low == "true"
        else:
            try:
                value = int(raw, 0)
            except ValueError:
                try:
                    value = float(raw)
                except ValueError:
                    value = raw
        out[key.replace("-", "_")] = value
    return out


DEFAULT_CONNECT_TIMEOUT_S = 5.0
MAX_CONNECT_TIMEOUT_S = 3600.0


def add_bus_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--interface", "-i", required=True, metavar="NAME",
                   help=f"python-can interface ({INTERFACE_EXAMPLES}; a wrong name lists the valid ones)")
    p.add_argument("--channel", "-c", default=None, help="bus channel, e.g. vcan0, PCAN_USBBUS1, 127.0.0.1:29536")
    p.add_argument("--bitrate", type=int, default=None, help="bit rate for interfaces that set it (bit/s)")
    p.add_argument("--option", "-o", action="append", metavar="KEY=VALUE",
                   help="extra python-can interface argument (repeatable), e.g. -o fd=true")
    p.add_argument("--connect-timeout", type=float, default=DEFAULT_CONNECT_TIMEOUT_S, metavar="S",
                   help="keep retrying a bus that is absent at start, with backoff, for this many seconds "
                        f"(0: one attempt; default {DEFAULT_CONNECT_TIMEOUT_S:g})")


def check_connect_timeout(args: argparse.Namespace) -> float:
    value = float(args.connect_timeout)
    if not 0.0 <= value <= MAX_CONNECT_TIMEOUT_S:
        raise InputError(f"--connect-timeout must be between 0 and {MAX_CONNECT_TIMEOUT_S:g} s, got {value:g}")
    return value


def bus_config(args: argparse.Namespace) -> BusConfig:
    from app.live.bus import BusConfig

    return BusConfig(args.interface, args.channel, args.bitrate, parse_options(args.option))


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "replay", help="replay a log onto a CAN bus with its original timing",
        description="Send the frames of LOG onto a CAN bus at their original pace (scaled by --rate). "
                    "Ctrl-C or SIGTERM stops cleanly and prints a summary.")
    p.add_argument("log", type=Path, help=log_help("log file"))
    add_format_file(p)
    add_bus_arguments(p)
    p.add_argument("--rate", type=float, default=1.0,
                   help="speed factor between 0.001 and 1000: 2 = twice as fast (default 1)")
    p.add_argument("--loop", action="store_true", help="start again at the end until Ctrl-C")
    p.add_argument("--ids", default=None, help="only these IDs, e.g. '0x108,0x118' (0x for hex, else decimal)")
    p.add_argument("--log-channel", type=int, action="append", default=None,
                   help="only frames from this channel of the log (0-based, repeatable)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def _chunks(path: Path) -> Generator[FrameChunk, None, None]:
    from app.ingest.readers import open_log

    reader = open_log(path)
    yield from reader.chunks()


def _progress_printer(tty: bool) -> Callable[[ReplayStats], None]:
    last_line = [0.0]

    def show(st: ReplayStats) -> None:
        line = (f"replay: {st.frames_sent:,} frames, log t = {st.log_time_s:8.2f} s, wall {st.wall_s:8.2f} s, "
                f"pacing p99 {st.pacing.percentile_ms(99):.2f} ms, send failures {st.send_failures}")
        if tty:
            print("\r" + line, end="", file=sys.stderr, flush=True)
        elif st.wall_s - last_line[0] >= 5.0:
            print(line, file=sys.stderr, flush=True)
            last_line[0] = st.wall_s

    return show


STOP_SIGNALS = {signal.SIGINT: "Ctrl-C", signal.SIGTERM: "SIGTERM"}


def run(args: argparse.Namespace) -> int:
    from app.errors import LogNotFoundError
    from app.live.bus import BusLink
    from app.live.replay import Replayer, check_rate, parse_ids

    # Every argument first: a bad one must not open (and then abandon) a bus.
    check_rate(args.rate)
    connect_timeout = check_connect_timeout(args)
    ids = parse_ids(args.ids)
    if args.log_channel and any(ch < 0 for ch in args.log_channel):
        raise InputError(f"--log-channel must be >= 0, got {args.log_channel}")
    cfg = bus_config(args)
    if not args.log.is_file():
        raise LogNotFoundError(f"log file not found: {args.log}")
    # Read the first chunk before touching the bus: a corrupt or unsupported log fails fast.
    probe = _chunks(args.log)
    next(probe, None)
    probe.close()
    link = BusLink(cfg)
    stopped_by: list[str] = []

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stopped_by.append(STOP_SIGNALS.get(signal.Signals(signum), f"signal {signum}"))
        if not link.connected:
            link.close()  # ends a connect that is still retrying
        replayer.stop()  # a running replay returns after the current frame

    tty = sys.stderr.isatty()
    show = _progress_printer(tty)
    replayer = Replayer(link, lambda: _chunks(args.log), rate=args.rate, loop=args.loop, ids=ids,
                        channels=args.log_channel, progress=show)
    previous = {sig: signal.signal(sig, on_signal) for sig in STOP_SIGNALS}
    try:
        try:
            link.open(connect_timeout)
        except Exception:
            if stopped_by:  # stopped while still waiting for the bus: nothing was sent
                replayer.stats.stopped_early = True
            else:
                raise
        stats = replayer.run() if not stopped_by else replayer.stats
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        link.close()
    if tty:
        print(file=sys.stderr)
    summary: dict[str, object] = dict(stats.summary())
    summary["bus"] = link.cfg.describe()
    summary["bus_reconnects"] = max(0, link.status.connects - 1)
    summary["stopped_by"] = stopped_by[0] if stopped_by else None
    if args.json:
        print(json.dumps(summary))
    else:
        how = f"stopped by {stopped_by[0]}" if stats.stopped_early and stopped_by else "done"
        print(f"replay {how}: {stats.frames_sent:,} frames sent onto {link.cfg.describe()} "
              f"in {stats.wall_s:.2f} s (log time {stats.log_time_s:.2f} s, rate {args.rate:g}, "
              f"loops {stats.loops_done})")
        print(f"  pacing error p50 {summary['pacing_p50_ms']:.2f} ms, p99 {summary['pacing_p99_ms']:.2f} ms, "
              f"max {summary['pacing_max_ms']:.2f} ms; skipped by filter {stats.frames_skipped:,}; "
              f"send failures {stats.send_failures:,}")
    if stats.stopped_early:
        return 143 if stopped_by and stopped_by[0] == "SIGTERM" else 130
    return 0
