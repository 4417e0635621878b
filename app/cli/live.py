"""``lashscope live --interface I --channel C --vehicle V``: analyse a live bus.

Receives the bus, records it to BLF (flushed as it arrives), decodes it with the vehicle's
DBC and signal map, prints tip-in/tip-out events with their metrics as each completes and a
status line every few seconds. Ctrl-C, SIGTERM or ``--duration`` stops it; the recording then
becomes a stored log with its analysis, as if it had been uploaded.

``--dbc`` instead of ``--vehicle`` decodes without the store (no events unless ``--map``),
writing the recording to ``--out``.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import sys
import threading
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING, Any

from app.cli.replay import add_bus_arguments, bus_config, check_connect_timeout
from app.errors import InputError

if TYPE_CHECKING:  # python-can, scipy and the analysis are imported when the command runs, not for --help
    from app.live.session import LiveSession


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = subparsers.add_parser(
        "live", help="analyse a live CAN bus: events as they complete, stored log + analysis at the end",
        description="Receive, record and analyse a live CAN bus until Ctrl-C, SIGTERM or --duration.")
    add_bus_arguments(p)
    p.add_argument("--vehicle", default=None, help="registered vehicle (DBC + signal map + driveline)")
    p.add_argument("--vehicle-version", type=int, default=None, help="vehicle version (default: latest)")
    p.add_argument("--dbc", type=Path, default=None, help="decode with this DBC instead of a vehicle")
    p.add_argument("--map", type=Path, default=None, help="signal map for --dbc (enables events)")
    p.add_argument("--out", type=Path, default=None, help="recording path with --dbc (default live-<id>.blf)")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="store (SQLite + files) for --vehicle (default $LASHSCOPE_DATA_DIR or ./lashscope-data)")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    p.add_argument("--no-analysis", action="store_true", help="store the log but do not analyse it")
    p.add_argument("--status-every", type=float, default=2.0, help="seconds between status lines (0: none)")
    p.add_argument("--json", action="store_true", help="print events and the final summary as JSON lines")
    p.set_defaults(func=run)


def _status_line(st: dict[str, Any]) -> str:
    lat = st["latency_ms"]["p50"]
    return (f"live {st['id']}: bus {st['bus']['state']}, {st['frames_received']:,} frames "
            f"({st['frames_per_s']:,.0f}/s), dropped {st['frames_dropped']}, bus errors {st['bus_errors']}, "
            f"decode errors {st['decode_errors']}, unknown-ID frames {st['unknown_id_frames']}, "
            f"events {st['events']}, latency p50 {'-' if lat is None else round(lat, 3)} ms")


def _event_line(ev: dict[str, Any]) -> str:
    m = ev.get("metrics") or {}

    def num(v: Any, scale: float = 1.0) -> str:  # a metric the event's sampling cannot resolve is "-", never nan
        return f"{scale * v:.1f}" if isinstance(v, int | float) and math.isfinite(v) else "-"

    what = (f"fluctuation {num(m.get('fluctuation_rpm'))} rpm (detrended), "
            f"gap-open {num(m.get('gap_open_time_s'), 1e3)} ms") if ev["included"] else ev["exclusion"]
    return f"event {ev['index']}: {ev['kind']} at t = {ev['t_cross_s']:.3f} s, {what}"


def run(args: argparse.Namespace) -> int:
    from app.live.analyzer import LiveAnalyzer
    from app.live.decoding import source_for
    from app.live.session import LiveSession, SessionOptions

    _check_args(args)
    done = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        done.set()

    def emit(ev: dict[str, Any]) -> None:
        print(json.dumps({"event": ev}, default=str) if args.json else _event_line(ev), flush=True)

    previous = {sig: signal.signal(sig, on_signal) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        if args.vehicle is not None:
            return _run_with_store(args, done, emit)
        source, units = source_for(args.dbc, args.map)
        session = LiveSession(bus_config(args), source, analyzer=LiveAnalyzer(units) if args.map else None,
                              options=SessionOptions(connect_timeout_s=args.connect_timeout))
        session.record_path = args.out or Path(f"live-{session.id}.blf")
        session.on_event = emit
        session.start()
        _watch(session, args, done)
        session.stop()
        summary = {"status": session.status(), "recording": str(session.record_path)}
        _finish(args, summary)
        return 0
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def _check_args(args: argparse.Namespace) -> None:
    """Refuse bad arguments before a bus, a store or a recording is opened."""
    if (args.vehicle is None) == (args.dbc is None):
        raise InputError("give either --vehicle (from the store) or --dbc (with optional --map)")
    if args.dbc is not None and args.data_dir is not None:
        raise InputError("--data-dir is the store for --vehicle; with --dbc the recording goes to --out")
    if args.vehicle is not None and (args.map is not None or args.out is not None):
        raise InputError("--map and --out go with --dbc; a --vehicle brings its own map and stores the recording")
    if args.duration is not None and not 0 < args.duration < float("inf"):
        raise InputError(f"--duration must be a positive number of seconds, got {args.duration:g}")
    if not 0 <= args.status_every < float("inf"):
        raise InputError(f"--status-every must be >= 0 seconds, got {args.status_every:g}")
    check_connect_timeout(args)
    if args.out is not None and not args.out.parent.is_dir():
        raise InputError(f"--out: directory {args.out.parent} does not exist")
    if args.data_dir is not None and args.data_dir.exists() and not args.data_dir.is_dir():
        raise InputError(f"--data-dir: {args.data_dir} is not a directory")


def _watch(session: LiveSession, args: argparse.Namespace, done: threading.Event) -> None:
    every = args.status_every if args.status_every > 0 else None
    waited = 0.0
    step = min(every or 0.5, 0.5)
    while not done.is_set() and session.state == "running":
        done.wait(step)
        waited += step
        if args.duration is not None and waited >= args.duration:
            break
        if every is not None and waited % every < step:
            print(_status_line(session.status()), file=sys.stderr, flush=True)


def _run_with_store(args: argparse.Namespace, done: threading.Event, emit: Any) -> int:
    from app.cli.vehicle_args import vehicle_not_found
    from app.errors import NotFoundError
    from app.jobs import JobRunner
    from app.live.decoding import source_for
    from app.live.manager import LiveManager, StartRequest
    from app.live.session import SessionOptions
    from app.settings import Settings, get_settings
    from app.storage.url import open_store

    settings = Settings(data_dir=args.data_dir) if args.data_dir is not None else get_settings()
    store = open_store(settings.store_location, files=settings.data_dir)  # LASHSCOPE_STORE_URL, if set
    try:
        store.get_vehicle(args.vehicle, args.vehicle_version)
    except NotFoundError as exc:
        names = [v.name for v in store.list_vehicles()]
        store.close()
        if args.vehicle in names:  # the vehicle is there, the version is not
            raise
        raise vehicle_not_found(args.vehicle, names) from exc
    runner = JobRunner(store)
    try:
        manager = LiveManager(store, settings.data_dir / "live", source_for, submit=runner.submit,
                              allowed_interfaces=frozenset({args.interface}))
        session = manager.start(StartRequest(bus_config(args), vehicle=args.vehicle,
                                             vehicle_version=args.vehicle_version, analyse=not args.no_analysis,
                                             options=SessionOptions(connect_timeout_s=args.connect_timeout)))
        session.on_event = emit
        _watch(session, args, done)
        fin = manager.stop(session.id)
        if fin.analysis_id is not None:
            job = store.get_analysis(fin.analysis_id).job
            print(f"analysing the stored log {fin.log_id} ...", file=sys.stderr, flush=True)
            runner.wait(job.id)
        summary = {"status": session.status(), "log_id": fin.log_id, "analysis_id": fin.analysis_id,
                   "note": fin.note}
        if fin.analysis_id is not None:
            rec = store.get_analysis(fin.analysis_id)
            summary["analysis"] = {"status": rec.job.status.value, "error": rec.job.error_detail,
                                   "summary": rec.summary}
        _finish(args, summary)
        return 0
    finally:
        runner.shutdown(wait=False)
        store.close()


def _finish(args: argparse.Namespace, summary: dict[str, Any]) -> None:
    st = summary["status"]
    if args.json:
        print(json.dumps(summary, default=str), flush=True)
        return
    print(_status_line(st))
    for key in ("recording", "log_id", "analysis_id", "note"):
        if summary.get(key):
            print(f"  {key.replace('_', ' ')}: {summary[key]}")
    if "analysis" in summary:
        a = summary["analysis"]
        print(f"  analysis {a['status']}" + (f": {a['error']}" if a["error"] else ""))
