"""The event store: a Parquet dataset, one row per event, partitioned by vehicle and date.

Layout (Hive partitioning, read by pyarrow, pandas and DuckDB alike)::

    ROOT/vehicle=<vehicle>/date=<YYYY-MM-DD | unknown>/<source>-<log hash>.parquet

One file per (log, partition), named by the log's content hash: writing a log again replaces
its file instead of adding duplicates, and each file is written to a hidden temporary name and
renamed into place, so a reader (or a batch killed mid-write) never sees half a file; pyarrow
skips names starting with ``.``. Partition values are URI-escaped (``/`` in a vehicle name).

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

from app.errors import StorageError
from app.fleet.rows import FLOAT_COLUMNS, STRING_COLUMNS

PARTITIONS = pa.schema([("vehicle", pa.string()), ("date", pa.string())])
TIME = pa.timestamp("us", tz="UTC")
SCHEMA = pa.schema(
    [(c, pa.string()) for c in STRING_COLUMNS]
    + [("analysed_at", TIME), ("time", TIME), ("event_index", pa.int32()), ("included", pa.bool_()),
       ("time_is_absolute", pa.bool_())]
    + [(c, pa.float64()) for c in FLOAT_COLUMNS]
)


def partition_dir(root: Path, vehicle: str, date: str) -> Path:
    return root / f"vehicle={quote(vehicle, safe='')}" / f"date={quote(date, safe='')}"


def write_rows(root: str | os.PathLike[str], rows: Sequence[dict[str, Any]], *, source: str,
               log_hash: str) -> list[Path]:
    """Write one log's rows, one file per (vehicle, date) partition, atomically; returns the files.

    A log written before under the same ``source`` is replaced partition by partition (its files
    are named by ``log_hash``); the rows' ``source`` column is set to ``source``. No rows, no file.
    """
    base = Path(root)
    groups: dict[tuple[str, str], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["vehicle"], row["date"]), []).append(row)
    written: list[Path] = []
    try:
        for (vehicle, date), part in sorted(groups.items()):
            folder = partition_dir(base, vehicle, date)
            folder.mkdir(parents=True, exist_ok=True)
            table = pa.Table.from_pylist([{k: r.get(k) for k in SCHEMA.names} | {"source": source}
                                           for r in part], schema=SCHEMA)
            final = folder / f"{source}-{log_hash}.parquet"
            tmp = folder / f".{final.name}.{uuid.uuid4().hex}.tmp"
            pq.write_table(table, tmp)
            tmp.replace(final)
            written.append(final)
    except OSError as exc:
        raise StorageError(f"event store {base}: cannot write ({exc.strerror or exc})") from exc
    return written


def dataset(root: str | os.PathLike[str]) -> ds.Dataset:
    """The event store as a pyarrow dataset (partition columns ``vehicle`` and ``date`` included)."""
    base = Path(root)
    if not base.is_dir():
        from app.errors import NotFoundError

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
    import pandas as pd

    frame = read_events(root, columns=["vehicle", "time", metric])
    frame = frame[frame["time"].notna() & frame[metric].notna()]
    if frame.empty:
        return pd.DataFrame({"vehicle": [], "week": [], "events": [], "median": []})
    week = frame["time"].dt.tz_convert(None).dt.to_period("W-SUN").dt.start_time.dt.date
    out = frame.assign(week=week).groupby(["vehicle", "week"], sort=True)[metric].agg(["size", "median"])
    return out.reset_index().rename(columns={"size": "events"})
