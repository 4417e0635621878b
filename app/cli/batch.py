"""``lashscope batch LOGS_OR_GLOB... --vehicle V --out DIR``: many logs on Dask, one record and event rows each."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from app.cli.log_args import add_format_file, log_help
from app.cli.vehicle_args import add_vehicle


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "batch", help="analyse many logs on Dask into an event store (Parquet)",
        description="Analyse every log (paths, globs such as 'logs/**/*.blf', or fsspec URLs) on a local Dask "
        "cluster or an existing scheduler. Each log gets a record under OUT/logs (failures with their error code; "
        "the batch goes on) and its events go to the Parquet event store OUT/events. Logs already done (same "
        "content) are skipped, so an interrupted batch resumes when run again.")
    p.add_argument("logs", nargs="+", metavar="LOG_OR_GLOB", help=log_help("logs, globs (quote them) or URLs"))
    add_format_file(p)
    add_vehicle(p)
    p.add_argument("--out", type=Path, required=True, help="output directory (records and event store)")
    p.add_argument("--vehicle-id", default=None, metavar="ID",
                   help="the fleet's name of the vehicle the logs come from (default: the registered "
                   "vehicle's name, else the driveline's)")
    p.add_argument("--vehicle-id-from-dir", action="store_true",
                   help="take each log's vehicle name from its parent folder (logs/<vehicle>/*.blf)")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="an existing Dask scheduler (tcp://host:8786) instead of a local cluster")
    p.add_argument("--workers", type=int, default=2, metavar="N",
                   help="local cluster worker processes, one thread each (default 2; 0: in-process, no Dask)")
    p.add_argument("--connect-timeout", type=float, default=10.0, metavar="S",
                   help="give up on an unreachable scheduler after this long (default 10 s)")
    p.add_argument("--diagnose", action="store_true", help="also diagnose each log (slower; outcome in the rows)")
    p.add_argument("--model", choices=["multibody", "two_inertia"], default="multibody")
    p.add_argument("--retry-failed", action="store_true", help="re-run logs whose earlier run failed")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from app.cli.vehicle_args import event_params, resolve_vehicle
    from app.errors import InputError
    from app.fleet.batch import BatchConfig, expand_sources, run_batch
    from app.fleet.work import BatchSpec
    from app.pipeline import AnalysisOptions, signal_routes

    if args.workers < 0:
        raise InputError(f"--workers {args.workers}: must be >= 0")
    if args.connect_timeout <= 0:
        raise InputError(f"--connect-timeout {args.connect_timeout:g}: must be > 0 s")
    sources = expand_sources(args.logs)
    # a bad vehicle, DBC or signal map fails here, before any worker starts
    inputs, vehicle_name = resolve_vehicle(args)
    signal_routes(inputs.database, inputs.signal_map)
    options = AnalysisOptions(model=args.model, events=event_params(args))
    cfg = BatchConfig(out=args.out, spec=BatchSpec(inputs, options.to_dict(), args.diagnose),
                      vehicle_id=args.vehicle_id or vehicle_name, vehicle_id_from_dir=args.vehicle_id_from_dir,
                      scheduler=args.scheduler, workers=args.workers, retry_failed=args.retry_failed,
                      connect_timeout_s=args.connect_timeout)
    summary = run_batch(sources, cfg, None if args.quiet else sys.stderr)
    print(f"{summary.total} logs: {summary.ok} analysed, {summary.failed} failed, {summary.skipped} already done; "
          f"{summary.events} events in {args.out / 'events'} ({summary.elapsed_s:.1f} s)")
    for f in summary.failures:
        print(f"  failed [{f['code']}] {f['log']}: {f['message']}")
    return 1 if summary.failed else 0
