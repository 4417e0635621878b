"""``lashscope fleet DIR``: per vehicle lash estimate and ripple over time from a batch's event store."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "fleet", help="per-vehicle lash and ripple from an event store; outliers flagged",
        description="Read the event store of DIR (a `lashscope batch --out` directory, its events/ folder, or a "
        "service data directory) and report per vehicle the gap-open time and total lash with an interval, the "
        "ripple per week, and the vehicles outside the fleet's band.")
    p.add_argument("dir", type=Path, help="batch output dir, data dir, or the event store itself")
    p.add_argument("--band-k", type=float, default=3.0, metavar="K", help="band half-width in robust SDs (default 3)")
    p.add_argument("--plot", type=Path, default=None, metavar="PNG", help="plot file (default DIR/fleet.png)")
    p.add_argument("--include-poor-tracking", action="store_true",
                   help="also use events of logs whose simulation does not track the measurement (left out by "
                   "default: their comparison is not valid)")
    p.add_argument("--json", action="store_true", help="print the report as JSON")
    p.set_defaults(func=run)


def store_root(path: Path) -> Path:
    """The event store under ``path``: ``path/events`` when it exists, else ``path`` itself."""
    return path / "events" if (path / "events").is_dir() else path


def _iv(q: dict[str, float], fmt: str) -> str:
    if not math.isfinite(q["median"]):
        return "-"
    return f"{q['median']:{fmt}} [{q['lo']:{fmt}}, {q['hi']:{fmt}}]"


def table(report: dict[str, Any]) -> str:
    lines = [f"{'vehicle':<16} {'logs':>5} {'events':>6} {'gap-open time (ms)':>22} {'total lash (deg)':>22} "
             f"{'ripple (rpm)':>22}  flags"]
    for v in report["vehicles"]:
        lines.append(f"{v['vehicle']:<16} {v['logs']:>5} {v['events']:>6} {_iv(v['gap_open_time_ms'], '.1f'):>22} "
                     f"{_iv(v['total_lash_deg'], '.2f'):>22} {_iv(v['ripple_rpm'], '.0f'):>22}  "
                     + ("; ".join(v["flags"]) or "-"))
    for q, band in report["bands"].items():
        unit = report["units"][q]
        lines.append(f"fleet band {q}: " + ("needs >= 3 vehicles" if band is None else
                                            f"{band['lo']:.3g} .. {band['hi']:.3g} {unit} "
                                            f"(median {band['center']:.3g})"))
    lines.append(poor_tracking_line(report["poor_tracking"]))
    return "\n".join(lines)


def poor_tracking_line(poor: dict[str, Any]) -> str:
    """How many events of logs that do not track were left out of (or kept in) the figures."""
    what = f"{poor['events']} events from {poor['logs']} logs whose simulation does not track the measurement"
    if poor["included"]:
        return f"{what} are included (--include-poor-tracking)"
    return f"{what} left out (--include-poor-tracking includes them)"


def run(args: argparse.Namespace) -> int:
    from app.fleet.report import fleet_report, report_png
    from app.storage.results import json_safe

    root = store_root(args.dir)
    report = fleet_report(root, k=args.band_k, include_poor=args.include_poor_tracking)
    plot = args.plot or (args.dir / "fleet.png")
    report["plot"] = str(report_png(report, plot))
    if args.json:
        sys.stdout.write(json.dumps(json_safe(report), indent=1) + "\n")
    else:
        print(table(report))
        print(f"plot: {plot}")
    return 0
