"""The event store: a Parquet dataset, one row per event, partitioned by vehicle and date (month).

Layout (Hive partitioning, read by pyarrow, pandas and DuckDB alike)::

    ROOT/vehicle=<vehicle>/month=<YYYY-MM | unknown>/<source>-<log hash>.parquet    one log's rows
    ROOT/vehicle=<vehicle>/month=<YYYY-MM | unknown>/compact-<id>.parquet          many logs' rows

The day is a column (``date``); partitions are months because a partition per vehicle and day
holds a few dozen events, and a query pays ~2-3 ms per file: 100k events in per-day files were
~4000 files and ~10 s to read, in per-month compacted files ~140 files.

Each log's rows are written to a file named by its content hash: writing a log again replaces
its file instead of adding duplicates, and each file is written to a hidden temporary name and
renamed into place, so a reader (or a batch killed mid-write) never sees half a file; pyarrow
skips names starting with ``.``. Partition values are URI-escaped (``/`` in a vehicle name).
:func:`compact` merges a partition's files into one (the batch does it at its end); a log written
after that replaces its rows in the compacted file as well. A compaction interrupted between
writing the merged file and removing its inputs leaves duplicates that the next compaction
removes (a per-log file wins over the same log's rows in a compacted file). One writer per
store at a time.

Query examples::

    import pandas as pd; pd.read_parquet("out/events")                       # pandas
    duckdb.sql("select vehicle, median(measured_fluctuation_rpm) from "
               "read_parquet('out/events/**/*.parquet', hive_partitioning=true) group by 1")
"""

from __future__ import annotations

import os
import uuid
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any
from urllib.parse import quote

import pyarrow as pa
import pyarrow.dataset as ds
import pyarrow.parquet as pq

from app import atomic
from app.errors import NotFoundError, StorageError
from app.fleet.rows import FLOAT_COLUMNS, STRING_COLUMNS

PARTITIONS = pa.schema([("vehicle", pa.string()), ("month", pa.string())])
TIME = pa.timestamp("us", tz="UTC")
SCHEMA = pa.schema(
    [(c, pa.string()) for c in (*STRING_COLUMNS, "date")]
    + [("analysed_at", TIME), ("time", TIME), ("event_index", pa.int32()), ("included", pa.bool_()),
       ("time_is_absolute", pa.bool_())]
    + [(c, pa.float64()) for c in FLOAT_COLUMNS]
)


COMPACT = "compact-"


def partition_dir(root: Path, vehicle: str, date: str) -> Path:
    """The folder of ``vehicle``'s rows of the month of ``date`` (``YYYY-MM-DD`` or ``unknown``)."""
    month = date[:7] if date != "unknown" else date
    return root / f"vehicle={quote(vehicle, safe='')}" / f"month={quote(month, safe='')}"


def _replace(table: pa.Table, final: Path) -> None:
    with atomic.atomic_path(final) as tmp:
        pq.write_table(table, tmp)


def _drop_logs(folder: Path, logs: set[tuple[str, str]]) -> None:
    """Remove the rows of ``logs`` ((source, log hash) pairs) from the compacted files in ``folder``."""
    for path in folder.glob(f"{COMPACT}*.parquet"):
        table = pq.read_table(path, schema=SCHEMA)
        keep = [(s, h) not in logs for s, h in zip(table["source"].to_pylist(), table["log_hash"].to_pylist(),
                                                     strict=True)]
        if all(keep):
            continue
        if any(keep):
            _replace(table.filter(pa.array(keep)), path)
        else:
            path.unlink()


def write_rows(root: str | os.PathLike[str], rows: Sequence[dict[str, Any]], *, source: str,
               log_hash: str) -> list[Path]:
    """Write one log's rows, one file per (vehicle, month) partition, atomically; returns the files.

    A log written before under the same ``source`` is replaced partition by partition (its files
    are named by ``log_hash``); the rows' ``source`` column is set to ``source``. No rows, no file.
    """
    base = Path(root)
    groups: dict[Path, list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault(partition_dir(base, row["vehicle"], row["date"]), []).append(row)
    written: list[Path] = []
    try:
        for folder, part in sorted(groups.items()):
            folder.mkdir(parents=True, exist_ok=True)
            table = pa.Table.from_pylist([{k: r.get(k) for k in SCHEMA.names} | {"source": source}
                                           for r in part], schema=SCHEMA)
            final = folder / f"{source}-{log_hash}.parquet"
            _replace(table, final)
            _drop_logs(folder, {(source, log_hash)})
            written.append(final)
    except OSError as exc:
        raise StorageError(f"event store {base}: cannot write ({exc.strerror or exc})") from exc
    return written


def compact(folders: Iterable[Path]) -> tuple[int, int]:
    """Merge each partition folder's files into one; returns (files before, files after)."""
    before = after = 0
    for folder in sorted(set(folders)):
        files = sorted(p for p in folder.glob("*.parquet"))
        before += len(files)
        singles = [p for p in files if not p.name.startswith(COMPACT)]
        if len(files) <= 1:
            after += len(files)
            continue
        try:
            tables = [pq.read_table(p, schema=SCHEMA) for p in singles]
            _drop_logs(folder, {(s, h) for t in tables for s, h in
                                zip(t["source"].to_pylist(), t["log_hash"].to_pylist(), strict=True)})
            tables += [pq.read_table(p, schema=SCHEMA) for p in folder.glob(f"{COMPACT}*.parquet")]
            olds = list(folder.glob("*.parquet"))
            _replace(pa.concat_tables(tables), folder / f"{COMPACT}{uuid.uuid4().hex}.parquet")
            for p in olds:
                p.unlink()
        except OSError as exc:
            raise StorageError(f"event store {folder}: cannot compact ({exc.strerror or exc})") from exc
        after += 1
    return before, after


def dataset(root: str | os.PathLike[str]) -> ds.Dataset:
    """The event store as a pyarrow dataset (partition columns ``vehicle`` and ``month`` included)."""
    base = Path(root)
    if not base.is_dir():
        raise NotFoundError(f"no event store at {base} (run `lashscope batch ... --out DIR` first)")
    return ds.dataset(base, format="parquet", schema=pa.unify_schemas([SCHEMA, PARTITIONS]),
                      partitioning=ds.partitioning(PARTITIONS, flavor="hive"))


def read_events(root: str | os.PathLike[str], columns: Iterable[str] | None = None,
                vehicle: str | None = None) -> Any:
    """The store (or one vehicle's rows) as a pandas DataFrame."""
    data = dataset(root)
    flt = (ds.field("vehicle") == vehicle) if vehicle is not None else None
    return data.to_table(columns=list(columns) if columns is not None else None, filter=flt).to_pandas()


def weekly_ripple(root: str | os.PathLike[str], metric: str = "measured_fluctuation_rpm") -> Any:
    """Median ``metric`` per vehicle per ISO week (Monday start) over events with metrics and an
    absolute time: a DataFrame with columns vehicle, week (date of the Monday), events, median."""
    return weekly_median(read_events(root, columns=["vehicle", "time", metric]), metric)


def weekly_median(frame: Any, metric: str = "measured_fluctuation_rpm") -> Any:
    """:func:`weekly_ripple` of rows already read (a DataFrame with vehicle, time and ``metric``)."""
    import pandas as pd  # lazy: pandas (a second of start-up) only for this summary

    frame = frame[frame["time"].notna() & frame[metric].notna()]
    if frame.empty:
        return pd.DataFrame({"vehicle": [], "week": [], "events": [], "median": []})
    week = frame["time"].dt.tz_convert(None).dt.to_period("W-SUN").dt.start_time.dt.date
    out = frame.assign(week=week).groupby(["vehicle", "week"], sort=True)[metric].agg(["size", "median"])
    return out.reset_index().rename(columns={"size": "events"})
