"""Batch benchmark: ``lashscope batch`` on a local Dask cluster against one process, and the event-store query.

Logs: ``--n`` demo drives of ``--duration`` s (the demo generator, :func:`app.demo.build.build_demo_log`),
seed ``1000 + i``, spread over ``--vehicles`` vehicles whose half-shaft lash differs (0.7-1.3 x nominal)
and over 20 weeks (one log every ~1.4 days), cached under ``bench/out/batch/logs``. Then, each
into a fresh output directory:

1. **throughput**: ``run_batch --workers 0`` (one process: hashing, rows, records included) and
   ``run_batch`` on a running local cluster of ``--workers`` processes (one connected client, as a
   program running batch after batch keeps it), alternating in rounds of ``--chunk`` logs so both
   sides see the same load on a shared machine (cluster start and worker warm-up reported apart);
   then the median wall and CPU time of one analysis on each side, from the per-log records, which
   separates work the cluster adds from time its workers spent waiting for a core;
2. **per-log overhead**: ``run_analysis`` in this process vs ``run_batch`` on a 1-worker cluster
   (hash, submit, analyse, rows, record) over ``--overhead-logs`` logs, alternating likewise, as
   wall time and as CPU time of every process involved (client, scheduler, worker);
3. **query**: an event store of ``--events`` rows (the real rows of step 2, replicated over 20
   vehicles and 26 weeks with a fixed seed, written as logs of 100 rows) queried for the median
   ripple per vehicle per week (:func:`app.fleet.store.weekly_ripple`, pyarrow + pandas) with one
   file per log, then after :func:`app.fleet.store.compact` (what a batch does at its end);
   DuckDB too when it is installed.

Usage::

    .venv/bin/python bench/batch.py [--n 100] [--duration 60] [--workers 2] [--events 100000]
"""

from __future__ import annotations

import argparse
import contextlib
import os
import shutil
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

OUT = REPO / "bench" / "out" / "batch"
DAY_S = 86_400.0


def make_logs(n: int, duration: float, vehicles: int) -> list[str]:
    from app.demo.build import DEMO_START_EPOCH_S, build_demo_log
    from app.demo.scenario import Scenario
    from app.settings import default_dbc_dir

    dbc = default_dbc_dir()
    paths = []
    for i in range(n):
        v = i % vehicles
        path = OUT / "logs" / f"{duration:g}s" / f"ev-{v:02d}" / f"log-{i:03d}.blf"
        if not path.exists():
            lash = 0.7 + 0.6 * v / max(vehicles - 1, 1)
            build_demo_log(path, dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml",
                           Scenario(duration_s=duration, seed=1000 + i, truth_changes={"gaps.halfshaft": lash}),
                           start_epoch_s=DEMO_START_EPOCH_S + i * 140 * DAY_S / n)
        paths.append(str(path))
    return paths


def config(out: Path, workers: int, scheduler: str | None = None):  # type: ignore[no-untyped-def]
    from app.fleet.batch import BatchConfig
    from app.fleet.work import BatchSpec

    return BatchConfig(out=out, spec=BatchSpec(inputs()), vehicle_id="bench", vehicle_id_from_dir=True,
                       workers=workers, scheduler=scheduler)


def local_cluster(workers: int):  # type: ignore[no-untyped-def]
    """A started local cluster and a client connected to it once (every round reuses the connection)."""
    from distributed import Client

    from app.fleet.cluster import local_cluster as start

    cluster = start(workers)
    return cluster, Client(cluster, set_as_default=False)


def _cpu_s() -> float:
    """CPU seconds (user + system) of this process (client, scheduler, result writing) and its children
    (the cluster's nannies and workers): the work done, whatever share of the cores the load left us."""
    import psutil

    me = psutil.Process()
    total = sum(me.cpu_times()[:2])
    for child in me.children(recursive=True):
        with contextlib.suppress(psutil.Error):  # a child that has just ended
            total += sum(child.cpu_times()[:2])
    return total


def throughput(paths: list[str], workers: int, chunk: int) -> None:
    """``run_batch --workers 0`` and ``run_batch`` on a running cluster of ``workers``, alternating in
    rounds of ``chunk`` logs so both see the same load (the machine is shared); the cluster is
    started and connected once (reported apart), as a user running batch after batch would keep it."""
    from app.fleet.batch import run_batch

    for d in ("single", "cluster", "cluster-warm"):
        shutil.rmtree(OUT / d, ignore_errors=True)
    clock = time.perf_counter()
    cluster, client = local_cluster(workers)
    start_s = time.perf_counter() - clock
    single_s = cluster_s = inside_s = 0.0
    single_ok = cluster_ok = events = 0
    try:
        run_batch(paths[-1:], config(OUT / "cluster-warm", workers), stream=None, client=client)
        warm = client.run(lambda dask_worker: dask_worker.lashscope_warm_s)
        for k in range(0, len(paths), chunk):
            part = paths[k:k + chunk]
            s = run_batch(part, config(OUT / "single", 0), stream=None)
            c = run_batch(part, config(OUT / "cluster", workers), stream=None, client=client)
            single_s, single_ok, events = single_s + s.elapsed_s, single_ok + s.ok, events + s.events
            cluster_s, cluster_ok = cluster_s + c.elapsed_s, cluster_ok + c.ok
            inside_s += sum(_task_seconds(OUT / "cluster", p) for p in part)
    finally:
        client.close()
        cluster.close()
    print(f"single process (--workers 0): {single_ok} logs, {events} events in {single_s:.1f} s = "
          f"{single_ok / single_s:.3f} logs/s", flush=True)
    print(f"cluster ({workers} workers; start {start_s:.1f} s, then each worker's imports and kernel load "
          f"{', '.join(f'{v:.1f}' for v in warm.values())} s, both apart): {cluster_ok} logs in {cluster_s:.1f} s = "
          f"{cluster_ok / cluster_s:.3f} logs/s; tasks busy {100 * inside_s / (workers * cluster_s):.0f} % of "
          f"the workers' wall time", flush=True)
    print(f"  throughput ratio cluster/single: {(cluster_ok / cluster_s) / (single_ok / single_s):.2f}x "
          f"(rounds of {chunk} logs, alternating)", flush=True)
    (s_wall, s_cpu), (c_wall, c_cpu) = _record_medians(OUT / "single"), _record_medians(OUT / "cluster")
    print(f"  one analysis (median): single {s_wall:.3f} s wall / {s_cpu:.3f} s CPU, in a cluster worker "
          f"{c_wall:.3f} s wall / {c_cpu:.3f} s CPU: the same work ({100 * (c_cpu / s_cpu - 1):+.1f} % CPU), "
          f"{c_wall / c_cpu:.2f}x its CPU in wall time (waiting for a core) against {s_wall / s_cpu:.2f}x; "
          f"with two free cores the ratio would be {workers * s_cpu / c_cpu:.2f}x", flush=True)


def _record_medians(out: Path) -> tuple[float, float]:
    """Median wall and task-thread CPU seconds of one analysis, from the records of a batch."""
    import json

    records = [json.loads(f.read_text()) for f in (out / "logs").glob("*.json")]
    return (statistics.median(r["elapsed_s"] for r in records), statistics.median(r["cpu_s"] for r in records))


def _task_seconds(out: Path, path: str) -> float:
    """The analysis time a log's record reports (measured inside the task)."""
    import json

    from app.log_source import content_hash

    return float(json.loads((out / "logs" / f"{content_hash(path)}.json").read_text())["elapsed_s"])


def overhead(paths: list[str], chunk: int) -> None:
    """Per-log cost: ``run_analysis`` in this process vs ``run_batch`` on a running 1-worker cluster
    (hash, submit, analyse, rows, record, compaction), alternating in rounds of ``chunk`` logs; as
    wall time and as CPU time of every process involved (which the machine's load does not inflate)."""
    from app.fleet.batch import run_batch
    from app.fleet.work import warm_worker
    from app.pipeline import run_analysis

    warm_worker()
    run_analysis(paths[0], inputs())
    for d in ("one", "one-warm"):
        shutil.rmtree(OUT / d, ignore_errors=True)
    cluster, client = local_cluster(1)
    direct_s = cluster_s = direct_cpu = cluster_cpu = inside_s = 0.0
    try:
        run_batch(paths[-1:], config(OUT / "one-warm", 1), stream=None, client=client)
        for k in range(0, len(paths), chunk):
            part = paths[k:k + chunk]
            clock, cpu = time.perf_counter(), _cpu_s()
            for p in part:
                run_analysis(p, inputs())
            direct_s += time.perf_counter() - clock
            direct_cpu += _cpu_s() - cpu
            cpu = _cpu_s()
            cluster_s += run_batch(part, config(OUT / "one", 1), stream=None, client=client).elapsed_s
            cluster_cpu += _cpu_s() - cpu
            inside_s += sum(_task_seconds(OUT / "one", p) for p in part)
    finally:
        client.close()
        cluster.close()
    n = len(paths)
    print(f"per-log cost over {n} logs: direct run_analysis {direct_s / n:.3f} s, cluster path (1 worker) "
          f"{cluster_s / n:.3f} s: overhead {100 * (cluster_s / direct_s - 1):+.1f} % wall (rounds of {chunk}, "
          f"alternating)", flush=True)
    print(f"  CPU time per log: direct {direct_cpu / n:.3f} s, cluster path {cluster_cpu / n:.3f} s (all processes): "
          f"overhead {100 * (cluster_cpu / direct_cpu - 1):+.1f} %; inside the task {inside_s / n:.3f} s wall, "
          f"around it (hash, scheduling, transfer, rows, record) {(cluster_s - inside_s) / n:.3f} s", flush=True)


def inputs():  # type: ignore[no-untyped-def]
    from app.pipeline import VehicleInputs
    from app.settings import default_dbc_dir
    from sim import load_vehicle

    dbc = default_dbc_dir()
    return VehicleInputs(load_vehicle("paper"), dbc / "lashscope_ev.dbc", dbc / "lashscope_ev.map.toml")


def synth_store(source: Path, root: Path, events: int) -> None:
    """``events`` rows from the real rows under ``source``, over 20 vehicles and 26 weeks (seed 7)."""
    import numpy as np
    import pandas as pd

    from app.fleet.rows import STRING_COLUMNS
    from app.fleet.store import read_events, write_rows

    shutil.rmtree(root, ignore_errors=True)
    real = read_events(source).astype({"vehicle": str, "date": str})
    rng = np.random.default_rng(7)
    picks = real.iloc[rng.integers(0, len(real), events)].reset_index(drop=True)
    base = pd.Timestamp("2025-01-06", tz="UTC")
    picks["time"] = base + pd.to_timedelta(rng.uniform(0, 26 * 7, events), unit="D")
    picks["vehicle"] = [f"veh-{k:02d}" for k in rng.integers(0, 20, events)]
    picks["measured_fluctuation_rpm"] *= rng.normal(1.0, 0.05, events)
    picks["date"] = picks["time"].dt.date.astype(str)
    picks = picks.sort_values(["vehicle", "date"]).reset_index(drop=True)
    text = list(STRING_COLUMNS)
    picks[text] = picks[text].astype(object).where(picks[text].notna(), None)
    for k, start in enumerate(range(0, events, 100)):
        part = picks.iloc[start:start + 100].to_dict("records")
        for key in {(r["vehicle"], r["date"]) for r in part}:
            rows = [r for r in part if (r["vehicle"], r["date"]) == key]
            write_rows(root, rows, source="bench", log_hash=f"{k:05d}-{key[1]}")


def query_times(root: Path, repeat: int) -> tuple[list[float], int]:
    from app.fleet.store import weekly_ripple

    times, groups = [], 0
    for _ in range(repeat):
        clock = time.perf_counter()
        groups = len(weekly_ripple(root))
        times.append(time.perf_counter() - clock)
    return times, groups


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", type=int, default=100)
    ap.add_argument("--duration", type=float, default=60.0)
    ap.add_argument("--vehicles", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--overhead-logs", type=int, default=12)
    ap.add_argument("--events", type=int, default=100_000)
    ap.add_argument("--chunk", type=int, default=20, help="logs per alternating round, single vs cluster")
    ap.add_argument("--chunk-overhead", type=int, default=6, help="logs per alternating round, direct vs cluster")
    ap.add_argument("--skip-batch", action="store_true")
    ap.add_argument("--skip-query", action="store_true")
    args = ap.parse_args()
    clock = time.perf_counter()
    paths = make_logs(args.n, args.duration, args.vehicles)
    print(f"logs: {len(paths)} x {args.duration:g} s over {args.vehicles} vehicles "
          f"(generated/cached in {time.perf_counter() - clock:.1f} s)", flush=True)

    if not args.skip_batch:
        print(f"load average before: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
        throughput(paths, args.workers, args.chunk)
        overhead(paths[:args.overhead_logs], args.chunk_overhead)
        print(f"load average after: {' '.join(f'{x:.2f}' for x in os.getloadavg())}", flush=True)
    if args.skip_query:
        return
    store = OUT / "query-store"
    clock = time.perf_counter()
    synth_store(OUT / "single" / "events", store, args.events)
    print(f"event store: {args.events} rows written in {time.perf_counter() - clock:.1f} s "
          f"({sum(1 for _ in store.rglob('*.parquet'))} files)", flush=True)
    times, groups = query_times(store, 3)
    print(f"query median ripple per vehicle per week (pyarrow + pandas), one file per log: "
          f"{statistics.median(times):.3f} s median of 3, {groups} groups", flush=True)
    from app.fleet.store import compact

    clock = time.perf_counter()
    before, after = compact(p.parent for p in store.rglob("*.parquet"))
    print(f"compacted {before} files into {after} in {time.perf_counter() - clock:.1f} s", flush=True)
    times, groups = query_times(store, 5)
    print(f"query median ripple per vehicle per week (pyarrow + pandas), compacted: {statistics.median(times):.3f} s "
          f"median of 5 (min {min(times):.3f} s), {groups} groups", flush=True)
    try:
        import duckdb
    except ImportError:
        print("DuckDB not installed: skipped")
    else:
        clock = time.perf_counter()
        duckdb.sql(f"select vehicle, date_trunc('week', time) w, median(measured_fluctuation_rpm) from "
                   f"read_parquet('{store}/**/*.parquet', hive_partitioning=true) group by all").fetchall()
        print(f"query with DuckDB: {time.perf_counter() - clock:.3f} s")


if __name__ == "__main__":
    main()
