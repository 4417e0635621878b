"""``lashscope demo``: build the bundled demo log (first run), analyse it, print and plot the results.

The demo log is made by the project's own tools: the paper preset simulated under a
scripted tip-in/tip-out drive (with a truth vehicle whose half-shaft clearance is 20 %
below nominal), sensor effects, DBC encoding through ``dbc/lashscope_ev.dbc`` and
python-can's BLF writer. It is generated deterministically into the data directory, then
stored and analysed through the same store and job runner as the REST API, so
``lashscope serve`` afterwards shows it.
"""

from __future__ import annotations

import argparse
import hashlib
from pathlib import Path
from typing import Any

DEMO_VEHICLE = "paper-demo"
DEMO_LOG = "lashscope-demo.blf"


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "demo", help="build and analyse the bundled demo drive",
        description="Build the demo log on first run, analyse it against the paper preset and save an overlay plot.")
    p.add_argument("--data-dir", type=Path, default=None, help="data directory (default ./lashscope-data)")
    p.add_argument("--rebuild", action="store_true", help="build the demo log again even if it exists")
    p.set_defaults(func=run)


def counter_gaps_table(doc: dict[str, Any]) -> str:
    """The alive counters the decoder checked: frames lost on the bus according to each counter."""
    gaps = (doc.get("ingest", {}).get("decode") or {}).get("counter_gaps") or []
    if not gaps:
        return "alive counters: none found in the decoded messages"
    lines = [f"{'alive counter':<30} {'frames':>7} {'pattern':<18} {'gaps':>5} {'missed':>6}  first gap (s)"]
    for g in gaps:
        first = "-" if g["first_gap_s"] is None else f"{g['first_gap_s']:.3f}"
        lines.append(f"{g['message'] + '.' + g['signal']:<30} {g['frames']:>7} {g['pattern']:<18} {g['gaps']:>5} "
                     f"{g['missed']:>6}  {first}")
    return "\n".join(lines)


def run(args: argparse.Namespace) -> int:
    from app.cli.report import drivability_table, events_table, metrics_table, summary_line, tracking_lines
    from app.demo.build import build_demo_log
    from app.demo.plot import overlay_png
    from app.ingest.inspect import inspect_log
    from app.jobs import JobRunner
    from app.pipeline import check_vehicle_files
    from app.settings import Settings
    from app.storage.records import JobStatus
    from app.storage.results import ResultFiles
    from app.storage.sqlite import SQLiteStore
    from sim import dump_toml, load_vehicle

    settings = Settings(**({"data_dir": args.data_dir} if args.data_dir else {}))
    root = settings.data_dir.resolve()
    demo_dir = root / "demo"
    log_path = demo_dir / DEMO_LOG
    dbc, smap = settings.dbc_dir / "lashscope_ev.dbc", settings.dbc_dir / "lashscope_ev.map.toml"
    if args.rebuild or not log_path.exists():
        print(f"building the demo log (paper preset, scripted tip-in/tip-out drive, {dbc.name}) ...", flush=True)
        frames = build_demo_log(log_path, dbc, smap)
        print(f"  {frames} CAN frames -> {log_path}")

    store = SQLiteStore(root)
    try:
        driveline = demo_dir / "paper.toml"
        driveline.write_text(dump_toml(load_vehicle("paper")), encoding="utf-8")
        vehicle, _ = store.add_vehicle(DEMO_VEHICLE, driveline=driveline, database=dbc, signal_map=smap,
                                       summary=check_vehicle_files(driveline, dbc, smap))
        digest = hashlib.sha256(log_path.read_bytes()).hexdigest()
        logrec = store.find_log_by_hash(digest)
        if logrec is None:
            info = inspect_log(log_path)
            tmp = store.temp_path(".blf")
            tmp.write_bytes(log_path.read_bytes())
            logrec, _ = store.add_log(tmp, sha256=digest, filename=DEMO_LOG, fmt=info["format"],
                                      frames=info["frames"], duration_s=info["duration_s"],
                                      start_time=info["start_time"], issues=info["issues"],
                                      meta={"start_clock": info["start_clock"], "channels": info["channels"]})
        print(f"analysing {logrec.id} ({logrec.frames} frames, {logrec.duration_s:.0f} s) with vehicle "
              f"{vehicle.name} v{vehicle.version} ...", flush=True)
        analysis = store.create_analysis(logrec.id, vehicle, {})
        runner = JobRunner(store, workers=1, in_process=True)  # nothing else to keep responsive here
        runner.submit(analysis.job.id)
        runner.wait(analysis.job.id)
        runner.shutdown(wait=True)
        job = store.get_job(analysis.job.id)
        if job.status is not JobStatus.DONE:
            print(f"lashscope demo: analysis failed [{job.error_code}]: {job.error_detail}")
            return 2
        files = ResultFiles(analysis.result_dir)
        png = overlay_png(files, demo_dir / "overlay.png",
                          title="demo: measured (truth: half-shaft gap -20 %) vs simulated (paper preset)")
        doc = files.doc
        print()
        print(summary_line(doc))
        print()
        print(events_table(doc))
        print()
        for line in tracking_lines(doc):  # none when the simulation tracks, as it should on the demo
            print(line)
        print(metrics_table(doc))
        print()
        feel = drivability_table(doc)
        if feel:
            print(feel)
            print()
        print(counter_gaps_table(doc))
        print()
        print(f"demo log:      {log_path}")
        print(f"overlay plot:  {png}")
        print(f"results:       {analysis.result_dir}  (analysis {analysis.id}, stored in {root / 'lashscope.sqlite3'})")
        base = f"http://{settings.host}:{settings.port}"
        print(f"next:          lashscope serve --data-dir {root}   then open the dashboard:")
        print(f"dashboard:     {base}/#/analysis/{analysis.id}")
        print(f"API:           curl '{base}/analyses/{analysis.id}/metrics'   (docs at {base}/docs)")
    finally:
        store.close()
    return 0
