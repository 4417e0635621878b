"""The Parquet event store: rows from a real analysis round-trip with their values; partitions; weekly query."""

from __future__ import annotations

import math
from datetime import UTC, datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow.dataset as ds
import pytest

from app.fleet.rows import event_rows
from app.fleet.store import SCHEMA, read_events, weekly_ripple, write_rows
from app.fleet.work import BatchSpec, analyse_log
from app.pipeline import AnalysisOptions, VehicleInputs
from sim import load_vehicle
from tests.fleet.conftest import DBC, MAP


@pytest.fixture(scope="module")
def analysed(fleet_logs: dict[str, Path]) -> dict[str, Any]:
    spec = BatchSpec(VehicleInputs(load_vehicle("paper"), DBC, MAP), AnalysisOptions(whole_log=False).to_dict())
    out = analyse_log(fleet_logs["log0"], spec)
    assert out["status"] == "ok", out
    return out


def test_rows_round_trip_with_their_values(analysed: dict[str, Any], tmp_path: Path) -> None:
    doc = analysed["doc"]
    rows = event_rows(doc, vehicle="car/7", log_hash="abc123", log_name="log0.blf", source="batch",
                      driveline="paper", diagnosis={"status": "explained", "top": ["torque_lag"]})
    files = write_rows(tmp_path, rows, source="batch", log_hash="abc123")
    assert [f.parent.parent.name for f in files] == ["vehicle=car%2F7"]  # escaped partition value
    back = read_events(tmp_path).sort_values("event_index").reset_index(drop=True)
    assert len(back) == len(doc["events"]) >= 4
    assert set(back["vehicle"]) == {"car/7"} and set(back["diagnosis_top"]) == {"torque_lag"}
    metrics = {m["event_index"]: m for m in doc["metrics"]}
    start = datetime.fromisoformat(doc["ingest"]["start_time"]).replace(tzinfo=UTC)
    for ev, row in zip(doc["events"], back.to_dict("records"), strict=True):
        assert row["event_index"] == ev["index"] and row["kind"] == ev["kind"]
        assert row["torque_step_nm"] == pytest.approx(ev["torque_after_nm"] - ev["torque_before_nm"])
        assert row["time"].to_pydatetime() == start + timedelta(seconds=ev["t_cross_s"])
        assert row["date"] == (start + timedelta(seconds=ev["t_cross_s"])).date().isoformat()
        m = metrics.get(ev["index"])
        if m is None:
            assert math.isnan(row["measured_fluctuation_rpm"]) and row["tracking"] is None
            continue
        assert row["measured_fluctuation_rpm"] == pytest.approx(m["measured"]["fluctuation_rpm"])
        assert row["simulated_fluctuation_rpm"] == pytest.approx(m["simulated"]["fluctuation_rpm"])
        assert row["tracking"] == m["tracking"]["verdict"] and row["nrmse"] == pytest.approx(m["nrmse"])
        gap = m["measured"]["gap_open_time_s"]
        assert (math.isnan(row["measured_gap_open_time_s"]) if gap is None
                else row["measured_gap_open_time_s"] == pytest.approx(gap))
    # pyarrow sees the same dataset with the partition columns typed
    table = ds.dataset(tmp_path, format="parquet", partitioning="hive").to_table()
    assert table.num_rows == len(rows) and set(SCHEMA.names) <= set(table.column_names)


def test_writing_a_log_again_replaces_its_rows(analysed: dict[str, Any], tmp_path: Path) -> None:
    rows = event_rows(analysed["doc"], vehicle="v", log_hash="h1", log_name="a.blf", source="batch", driveline="p")
    write_rows(tmp_path, rows, source="batch", log_hash="h1")
    write_rows(tmp_path, rows, source="batch", log_hash="h1")
    write_rows(tmp_path, rows[:2], source="service", log_hash="h1")
    frame = read_events(tmp_path)
    assert len(frame) == len(rows) + 2
    assert (frame["source"] == "service").sum() == 2
    assert not list(tmp_path.rglob(".*.tmp"))


def test_no_absolute_time_goes_to_the_unknown_partition(analysed: dict[str, Any], tmp_path: Path) -> None:
    doc = {**analysed["doc"], "ingest": {**analysed["doc"]["ingest"], "start_time": None}}
    rows = event_rows(doc, vehicle="v", log_hash="h", log_name="a.asc", source="batch", driveline="p")
    write_rows(tmp_path, rows, source="batch", log_hash="h")
    frame = read_events(tmp_path)
    assert set(frame["date"]) == {"unknown"} and frame["time"].isna().all() and not frame["time_is_absolute"].any()
    assert frame["t_log_s"].tolist() == [e["t_cross_s"] for e in doc["events"]]


def _synthetic_rows(vehicle: str, start: datetime, ripple: list[float]) -> list[dict[str, Any]]:
    return [{"vehicle": vehicle, "date": (start + timedelta(days=k)).date().isoformat(), "log_hash": f"{vehicle}{k}",
             "time": start + timedelta(days=k), "measured_fluctuation_rpm": r, "event_index": k, "kind": "tip_in",
             "included": True, "time_is_absolute": True} for k, r in enumerate(ripple)]


def test_weekly_median_ripple(tmp_path: Path) -> None:
    monday = datetime(2025, 3, 3, 12, tzinfo=UTC)  # a Monday
    rows = _synthetic_rows("a", monday, [100, 300, 200, 0, 0, 0, 0, 10, 20]) + _synthetic_rows("b", monday, [50.0])
    rows[3]["measured_fluctuation_rpm"] = float("nan")  # no metric: left out
    rows[4:7] = [dict(r, measured_fluctuation_rpm=400.0) for r in rows[4:7]]
    for r in rows:
        write_rows(tmp_path, [r], source="batch", log_hash=r["log_hash"])
    out = weekly_ripple(tmp_path)
    got = {(v, str(w)): (int(n), float(m)) for v, w, n, m in out[["vehicle", "week", "events", "median"]].to_numpy()}
    assert got == {("a", "2025-03-03"): (6, 350.0), ("a", "2025-03-10"): (2, 15.0), ("b", "2025-03-03"): (1, 50.0)}
    assert isinstance(out, pd.DataFrame) and np.isfinite(out["median"]).all()


def test_compaction_merges_a_partition_and_later_writes_replace_rows(analysed: dict[str, Any],
                                                                     tmp_path: Path) -> None:
    from app.fleet.store import compact

    rows = event_rows(analysed["doc"], vehicle="v", log_hash="x", log_name="a.blf", source="batch", driveline="p")
    for h in ("h1", "h2", "h3"):
        files = write_rows(tmp_path, [dict(r, log_hash=h) for r in rows], source="batch", log_hash=h)
    folder = files[0].parent
    assert folder.name == f"month={rows[0]['date'][:7]}"
    before = read_events(tmp_path).sort_values(["log_hash", "event_index"]).reset_index(drop=True)
    assert compact([folder]) == (3, 1)
    merged = read_events(tmp_path).sort_values(["log_hash", "event_index"]).reset_index(drop=True)
    pd.testing.assert_frame_equal(merged, before)
    # h2 analysed again with other values: its rows are replaced, not added
    write_rows(tmp_path, [dict(r, log_hash="h2", measured_fluctuation_rpm=1.0) for r in rows], source="batch",
               log_hash="h2")
    frame = read_events(tmp_path)
    assert len(frame) == 3 * len(rows)
    assert (frame.loc[frame["log_hash"] == "h2", "measured_fluctuation_rpm"] == 1.0).all()
    assert (frame.loc[frame["log_hash"] == "h1", "measured_fluctuation_rpm"] != 1.0).any()
    assert compact([folder]) == (2, 1) and len(read_events(tmp_path)) == 3 * len(rows)
