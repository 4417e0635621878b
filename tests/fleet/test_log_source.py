"""Logs opened from paths, binary file objects and fsspec URLs decode alike; content hashes name them."""

from __future__ import annotations

import hashlib
from datetime import datetime
from pathlib import Path

import numpy as np
import pytest

from app.errors import LogNotFoundError
from app.log_source import content_hash, is_url, source_name
from app.pipeline import decode_log
from tests.fleet.conftest import DBC, MAP


def test_file_object_decodes_like_the_path(fleet_logs: dict[str, Path]) -> None:
    path = fleet_logs["log0"]
    by_path, ingest_path = decode_log(path, DBC, MAP)
    with path.open("rb") as fh:
        by_file, ingest_file = decode_log(fh, DBC, MAP)
    assert sorted(by_path) == sorted(by_file)
    for name in by_path:
        np.testing.assert_array_equal(by_path[name].t, by_file[name].t)
        np.testing.assert_array_equal(by_path[name].values, by_file[name].values)
    assert ingest_path["frames"] == ingest_file["frames"] > 1000
    # the demo's fixed start, 1_718_000_000 s since the epoch, as the BLF header stores it (local clock, no zone)
    start = datetime.fromisoformat(ingest_path["start_time"])
    assert abs((start - datetime(2024, 6, 10, 6, 13, 20)).total_seconds()) < 14 * 3600
    assert ingest_file["start_time"] == ingest_path["start_time"]


def test_fsspec_memory_url_decodes_like_the_path(fleet_logs: dict[str, Path]) -> None:
    fsspec = pytest.importorskip("fsspec")
    path = fleet_logs["log1"]
    url = "memory://fleet-test/log1.blf"
    with fsspec.open(url, "wb") as fh:
        fh.write(path.read_bytes())
    try:
        by_url, _ = decode_log(url, DBC, MAP)
        by_path, _ = decode_log(path, DBC, MAP)
        np.testing.assert_array_equal(by_url["motor_speed_rpm"].values, by_path["motor_speed_rpm"].values)
        assert content_hash(url) == hashlib.sha256(path.read_bytes()).hexdigest() == content_hash(path)
        with pytest.raises(LogNotFoundError, match=r"memory://fleet-test/none\.blf: no such log"):
            decode_log("memory://fleet-test/none.blf", DBC, MAP)
    finally:
        fsspec.filesystem("memory").rm("/fleet-test", recursive=True)


def test_hash_of_a_file_object_rewinds_it(fleet_logs: dict[str, Path]) -> None:
    path = fleet_logs["log2"]
    with path.open("rb") as fh:
        fh.seek(10)
        assert content_hash(fh) == hashlib.sha256(path.read_bytes()[10:]).hexdigest()
        assert fh.tell() == 10


def test_names_and_urls() -> None:
    assert is_url("s3://bucket/a.blf") and not is_url("/data/a.blf") and not is_url("file:///data/a.blf")
    assert source_name("s3://bucket/car/a.blf") == "a.blf" and source_name(Path("/x/b.asc")) == "b.asc"
    with pytest.raises(LogNotFoundError, match=r"nothing\.blf: no such log"):
        content_hash("/nonexistent/nothing.blf")
