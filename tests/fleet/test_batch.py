"""``lashscope batch``: a real LocalCluster and the in-process path give the same rows; bad logs become
error rows; re-runs skip, interrupted runs resume; bad vehicles and unreachable schedulers are one message."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pandas as pd
import pytest

from app.cli import main
from app.fleet.batch import BatchConfig, BatchSummary, expand_sources, read_record, run_batch
from app.fleet.cluster import SchedulerUnreachableError
from app.fleet.store import read_events
from app.fleet.work import BatchSpec
from app.log_source import content_hash
from app.pipeline import AnalysisOptions, VehicleInputs
from sim import load_vehicle
from tests.fleet.conftest import DBC, MAP

pytest.importorskip("distributed")

SPEC = BatchSpec(VehicleInputs(load_vehicle("paper"), DBC, MAP), AnalysisOptions(whole_log=False).to_dict())
METRIC_COLUMNS = ["event_index", "kind", "measured_fluctuation_rpm", "simulated_fluctuation_rpm",
                  "measured_gap_open_time_s", "torque_step_nm", "tracking"]


def _config(out: Path, workers: int, **kw: object) -> BatchConfig:
    return BatchConfig(out=out, spec=SPEC, vehicle_id="fleet", vehicle_id_from_dir=True, workers=workers,
                       **kw)  # type: ignore[arg-type]


def _sorted_rows(out: Path) -> pd.DataFrame:
    frame = read_events(out / "events").sort_values(["log_hash", "event_index"]).reset_index(drop=True)
    return frame[["vehicle", "log_hash", *METRIC_COLUMNS]].astype({"vehicle": str})


@pytest.fixture(scope="module")
def in_process(fleet_logs: dict[str, Path], tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, BatchSummary]:
    out = tmp_path_factory.mktemp("batch-inproc")
    sources = [str(p) for p in fleet_logs.values()] + [str(fleet_logs["log0"].parent / "missing.blf")]
    return out, run_batch(sources, _config(out, workers=0), stream=None)


def test_in_process_batch_records_every_log(in_process: tuple[Path, BatchSummary],
                                            fleet_logs: dict[str, Path]) -> None:
    out, summary = in_process
    assert (summary.total, summary.ok, summary.failed, summary.skipped) == (5, 3, 2, 0)
    codes = {Path(f["log"]).name: f["code"] for f in summary.failures}
    assert codes == {"broken.blf": "log_format", "missing.blf": "file_not_found"}
    broken = read_record(out, content_hash(fleet_logs["broken"]))
    assert broken is not None and broken["status"] == "failed" and "broken.blf" in broken["message"]
    for name in ("log0", "log1", "log2"):
        rec = read_record(out, content_hash(fleet_logs[name]))
        assert rec is not None and rec["status"] == "ok" and rec["driveline"] == "paper"
        assert rec["events"] == rec["summary"]["events"] >= 2
    rows = _sorted_rows(out)
    assert len(rows) == summary.events
    assert set(rows["vehicle"]) == {"car-a", "car-b"}  # from the parent folders
    assert rows["measured_fluctuation_rpm"].notna().sum() >= 6


def test_local_cluster_gives_the_same_rows(in_process: tuple[Path, BatchSummary], fleet_logs: dict[str, Path],
                                           tmp_path: Path) -> None:
    good = [str(fleet_logs[k]) for k in ("log0", "log1", "log2")]
    summary = run_batch([*good, str(fleet_logs["broken"])], _config(tmp_path, workers=1), stream=None)
    assert (summary.ok, summary.failed) == (3, 1)
    assert summary.failures[0]["code"] == "log_format"
    assert summary.timings_s["cluster_start"] > 0 and summary.timings_s["analyse"] > 0
    pd.testing.assert_frame_equal(_sorted_rows(tmp_path), _sorted_rows(in_process[0]))
    # a second run finds everything done: nothing analysed, no cluster started
    again = run_batch([*good, str(fleet_logs["broken"])], _config(tmp_path, workers=1), stream=None)
    assert (again.ok, again.failed, again.skipped) == (0, 0, 4) and "cluster_start" not in again.timings_s


def test_batches_on_one_connected_client_warm_each_worker_once(in_process: tuple[Path, BatchSummary],
                                                               fleet_logs: dict[str, Path], tmp_path: Path) -> None:
    from distributed import Client

    from app.fleet.cluster import local_cluster

    cluster = local_cluster(1)
    client = Client(cluster, set_as_default=False)
    try:
        first = run_batch([str(fleet_logs["log0"])], _config(tmp_path, workers=1), stream=None, client=client)
        warm = client.run(lambda dask_worker: dask_worker.lashscope_warm_s)
        second = run_batch([str(fleet_logs[k]) for k in ("log1", "log2")], _config(tmp_path, workers=1),
                           stream=None, client=client)
        assert client.run(lambda dask_worker: dask_worker.lashscope_warm_s) == warm  # not warmed again
        assert (first.ok, second.ok, second.skipped) == (1, 2, 0) and client.status == "running"
    finally:
        client.close()
        cluster.close()
    pd.testing.assert_frame_equal(_sorted_rows(tmp_path), _sorted_rows(in_process[0]))  # the broken log has none


def test_rerun_resumes_after_an_interruption(fleet_logs: dict[str, Path], tmp_path: Path) -> None:
    sources = [str(fleet_logs[k]) for k in ("log0", "log1", "log2", "broken")]
    first = run_batch(sources, _config(tmp_path, workers=0), stream=None)
    assert (first.ok, first.failed) == (3, 1)
    before = _sorted_rows(tmp_path)
    # a kill after log1's rows were written but before its record: its record is missing
    (tmp_path / "logs" / f"{content_hash(fleet_logs['log1'])}.json").unlink()
    resumed = run_batch(sources, _config(tmp_path, workers=0), stream=None)
    assert (resumed.ok, resumed.failed, resumed.skipped) == (1, 0, 3)
    pd.testing.assert_frame_equal(_sorted_rows(tmp_path), before)  # rows replaced, not duplicated
    retried = run_batch(sources, _config(tmp_path, workers=0, retry_failed=True), stream=None)
    assert (retried.ok, retried.failed, retried.skipped) == (0, 1, 3)


def test_same_content_twice_is_analysed_once(fleet_logs: dict[str, Path], tmp_path: Path) -> None:
    copy = tmp_path / "copy.blf"
    copy.write_bytes(fleet_logs["log2"].read_bytes())
    summary = run_batch([str(fleet_logs["log2"]), str(copy)], _config(tmp_path / "out", workers=0), stream=None)
    assert (summary.ok, summary.skipped) == (1, 1)


def test_unreachable_scheduler_is_one_error(fleet_logs: dict[str, Path], tmp_path: Path) -> None:
    with socket.socket() as s:  # a loopback port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg = _config(tmp_path, workers=1, scheduler=f"tcp://127.0.0.1:{port}", connect_timeout_s=2.0)
    with pytest.raises(SchedulerUnreachableError, match=f"no Dask scheduler reachable at tcp://127.0.0.1:{port}"):
        run_batch([str(fleet_logs["log0"])], cfg, stream=None)
    assert read_record(tmp_path, content_hash(fleet_logs["log0"])) is None  # nothing recorded as done


def test_cli_unreachable_scheduler(fleet_logs: dict[str, Path], tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["batch", str(fleet_logs["log0"]), "--vehicle", "paper", "--out", str(tmp_path),
                 "--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "1", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("lashscope: error [scheduler_unreachable]: no Dask scheduler reachable")
    assert err.count("\n") == 1


def test_cli_vehicle_missing_or_unknown(fleet_logs: dict[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["batch", str(fleet_logs["log0"]), "--out", str(tmp_path)])
    assert exc.value.code == 2 and "the following arguments are required: --vehicle" in capsys.readouterr().err
    code = main(["batch", str(fleet_logs["log0"]), "--vehicle", "nosuchcar", "--out", str(tmp_path), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "[vehicle_not_found]" in err and "nosuchcar" in err and "presets: " in err
    assert not (tmp_path / "logs").exists()  # refused before any log was touched


def test_cli_glob_that_matches_nothing(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(["batch", str(tmp_path / "*.blf"), "--vehicle", "paper", "--out", str(tmp_path / "o")])
    assert code == 2 and "[invalid_input]: no log matches" in capsys.readouterr().err


def test_cli_in_process_then_fleet_report(fleet_logs: dict[str, Path], tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    pattern = str(fleet_logs["log0"].parent.parent / "**" / "*.blf")
    assert expand_sources([pattern]) == sorted(str(p) for p in fleet_logs.values())
    code = main(["batch", pattern, "--vehicle", "paper", "--out", str(tmp_path), "--workers", "0",
                 "--vehicle-id-from-dir", "--quiet"])
    text = capsys.readouterr().out
    assert code == 1 and "4 logs: 3 analysed, 1 failed, 0 already done" in text  # 1: some logs failed
    assert "failed [log_format]" in text and "broken.blf" in text
    assert main(["fleet", str(tmp_path), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert [v["vehicle"] for v in report["vehicles"]] == ["car-a", "car-b"]
    assert [v["logs"] for v in report["vehicles"]] == [2, 1]
    assert report["bands"]["total_lash_deg"] is None and report["flagged"] == []  # two vehicles: no band
    assert Path(report["plot"]).stat().st_size > 10_000
