"""A damaged log is never analysed without a word: ``analyze`` and ``diagnose`` state what reading lost
(frames and seconds) on the command line and in their JSON, as the analysis payload does for the REST API."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from app.cli import main
from app.demo.build import build_demo_log
from app.demo.scenario import Scenario
from app.ingest.frames import FrameChunk
from app.ingest.readers import open_log
from app.ingest.readreport import read_summary
from app.pipeline import decode_log
from app.settings import default_dbc_dir

DBC = default_dbc_dir()


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """The 40 s demo drive as BLF, and the same file cut at 100 kB."""
    folder = tmp_path_factory.mktemp("read")
    whole = folder / "drive.blf"
    build_demo_log(whole, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml", Scenario(duration_s=40.0))
    cut = folder / "cut.blf"
    cut.write_bytes(whole.read_bytes()[:100_000])
    return whole, cut


def _frames(path: Path) -> tuple[int, float]:
    with open_log(path) as log:
        chunk = FrameChunk.concat(list(log.chunks()))
    return len(chunk), float(chunk.t_ns[-1] - chunk.t_ns[0]) / 1e9


def test_truncated_blf_losses_from_its_header(logs: tuple[Path, Path]) -> None:
    whole, cut = logs
    n_whole, span_whole = _frames(whole)
    n_cut, span_cut = _frames(cut)
    _, ingest = decode_log(cut, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml")
    read = ingest["read"]
    assert read["damaged"] and read["truncated"] and read["frames_read"] == n_cut
    assert read["frames_lost"] == n_whole - n_cut  # the header counts every frame the logger wrote
    assert read["seconds_lost"] == pytest.approx(span_whole - span_cut, abs=0.05)  # header stop time - last frame
    where = read["problems"][0]["where"]  # the end of the last whole container before the cut
    assert read["problems"][0]["kind"] == "truncated" and where.startswith("byte offset ")
    assert 50_000 < int(where.split()[-1]) < 100_000
    assert f"{n_whole - n_cut} frame(s)" in read["note"] and f"{span_cut:.1f} s that were read" in read["note"]
    _, ingest = decode_log(whole, DBC / "lashscope_ev.dbc", DBC / "lashscope_ev.map.toml")
    assert ingest["read"]["damaged"] is False and ingest["read"]["note"] is None


def test_skipped_lines_count_as_frames_lost(tmp_path: Path) -> None:
    lines = [f"({1_700_000_000 + i / 100:.6f}) can0 100#0011223344556677\n" for i in range(1000)]
    for k in (100, 200, 300):
        lines[k] = lines[k].replace("#00", "#Z0")
    path = tmp_path / "bad.log"
    path.write_text("".join(lines))
    with open_log(path) as log:
        n = sum(len(c) for c in log.chunks())
        read = read_summary(log.meta, log.report, n, 9.99)
    assert n == 997 and read["damaged"] and not read["truncated"]
    assert read["frames_lost"] == 3 and read["problem_count"] == 3
    assert read["seconds_lost"] == pytest.approx(3 * 9.99 / 997) and read["seconds_estimated"]  # at the frame rate
    assert not read["estimated"] and "; 3 frame(s) (about 0.0 s) lost" in read["note"]  # each skipped line is one
    assert [p["where"] for p in read["problems"]] == ["line 101", "line 201", "line 301"]


def test_analyze_states_the_truncation(logs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]) -> None:
    _, cut = logs
    assert main(["analyze", str(cut), "--vehicle", "paper", "--no-whole-log"]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0].startswith("WARNING [log_truncated]: the log is truncated (truncated at byte offset ")
    assert main(["analyze", str(cut), "--vehicle", "paper", "--no-whole-log", "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    read = doc["summary"]["read"]
    assert read == doc["ingest"]["read"] and read["truncated"] and read["frames_lost"] > 5000
    assert f"about {read['frames_lost']} frame(s) ({read['seconds_lost']:.1f} s) lost" in out[0]  # s: BLF header


def test_diagnose_states_the_truncation(logs: tuple[Path, Path], capsys: pytest.CaptureFixture[str],
                                        tmp_path: Path) -> None:
    _, cut = logs
    out_file = tmp_path / "d.json"
    assert main(["diagnose", str(cut), "--vehicle", "paper", "--quiet", "--out", str(out_file)]) == 0
    first = capsys.readouterr().out.splitlines()[0]
    doc = json.loads(out_file.read_text())
    assert doc["read"]["truncated"] and first == f"WARNING [log_truncated]: {doc['read']['note']}"
