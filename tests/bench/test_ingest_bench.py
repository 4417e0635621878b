"""``bench/ingest.py`` in a small form: each path runs as its own child process of the script, as the benchmark's
figures are taken. A child once imported ``bench/sim.py`` for the simulator package (the script's folder comes first
on ``sys.path``) and every load_signals row failed; this catches that kind of break without the full 300k-frame run.
The timings are the benchmark's to print, not this test's."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bench.ingest import MF4_SAMPLE
from tests.conftest import DATA, REPO


@pytest.mark.slow
def test_every_path_of_the_ingest_benchmark_runs_on_both_logs(tmp_path: Path) -> None:
    run = subprocess.run([sys.executable, "bench/ingest.py", "--seconds", "10", "--repeat", "1", "--formats", "blf",
                          "--mf4-copies", "1", "--workdir", str(tmp_path)], cwd=REPO, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0 and "failed" not in run.stdout, run.stdout[-3000:] + run.stderr[-3000:]
    cells = [line.split("|")[0].rsplit(None, 1) for line in run.stdout.splitlines()
             if line.count("|") >= 3 and not line.startswith("path")]  # the path's name, then its frames
    rows = [c[0] for c in cells]
    assert rows.count("blf load_signals lashscope_ev") == 1 and rows.count("blf load_signals foreign_ev") == 1, rows
    mf4 = (DATA / MF4_SAMPLE).exists()  # the MF4 row reads the public sample in ../shared; a clone without it has none
    assert len(rows) == (10 if mf4 else 9) and (rows[-1] == "mf4 decoder vs asammdf bus logging") == mf4, rows
    frames = [int(c[1].replace(",", "")) for c in cells if c[0].startswith("blf load_signals")]
    assert len(frames) == 3 and all(f > 10_000 for f in frames), frames
