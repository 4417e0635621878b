"""``decode`` without a map streams every message to its own Parquet/CSV table with bounded memory."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow.csv as pacsv
import pyarrow.parquet as pq
import pytest

from app.cli.decode import decode_log
from app.ingest.database import load_database
from app.ingest.decode import DecodedMessage, VectorDecoder
from app.ingest.readers import open_log
from app.ingest.tables import MessageTables
from tests.ingest.test_decode_pipeline import write_reference_blf

DBC = Path(__file__).resolve().parents[2] / "dbc" / "lashscope_ev.dbc"


@pytest.fixture(scope="module")
def log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("tables") / "drive.blf"
    write_reference_blf(path, seconds=20.0, sna_speed_at=(3, 700))
    return path


def test_streamed_tables_equal_decoding_at_once(log: Path, tmp_path: Path) -> None:
    loaded = load_database(DBC)
    chunk_frames, budget = 500, 40_000
    tables = MessageTables(tmp_path / "messages", ("parquet", "csv"), rows_per_group=300, budget_bytes=budget)
    report = decode_log(log, loaded, tables=tables, chunk_frames=chunk_frames)
    # what decoding the whole log at once gives
    decoder = VectorDecoder(loaded.db)
    parts: dict[str, list[DecodedMessage]] = {}
    for chunk in open_log(log).chunks():
        for name, dm in decoder.decode(chunk).items():
            parts.setdefault(name, []).append(dm)
    whole = {name: DecodedMessage.concat(p) for name, p in parts.items()}
    assert report.frames_decoded == sum(len(m) for m in whole.values()) > 5000
    assert sorted(p.name for p in tables.paths) == sorted(f"{n}.{f}" for n in whole for f in ("parquet", "csv"))
    for name, dm in whole.items():
        pf = pq.ParquetFile(tmp_path / "messages" / f"{name}.parquet")
        table = pf.read()
        assert table.column_names == ["t_s", "bus", *dm.signals]
        np.testing.assert_array_equal(table["t_s"].to_numpy(), dm.t_ns / 1e9)
        np.testing.assert_array_equal(table["bus"].to_numpy(), dm.channel)
        for sig, values in dm.signals.items():
            np.testing.assert_array_equal(table[sig].to_numpy(), values, err_msg=f"{name}.{sig}")
        if len(dm) > 600:
            assert pf.metadata.num_row_groups > 1  # written as it came, not at the end
        assert pacsv.read_csv(tmp_path / "messages" / f"{name}.csv").num_rows == len(dm)
    assert np.isnan(pq.read_table(tmp_path / "messages" / "MCU_Speed.parquet")["MotorSpeed"].to_numpy()[3])
    # memory: never more than the budget plus one chunk's decoded rows (8 bytes per value, <= 12 columns)
    assert tables.peak_bytes <= budget + chunk_frames * 12 * 8
    assert tables.held_bytes == 0


def test_cli_prints_written_files(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from app.cli import main

    assert main(["decode", str(log), "--dbc", str(DBC), "--out", str(tmp_path), "--format", "parquet"]) == 0
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'messages' / 'MCU_Speed.parquet'}" in out
    assert not list((tmp_path / "messages").glob("*.csv"))


def test_bad_format_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="formats"):
        MessageTables(tmp_path, ("xlsx",))
