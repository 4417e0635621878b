"""``bench/knee.py`` as a user runs it: both rates print a row whose screened and full knee fits agree to the last
bit on every rise window, and the ``analyze_signals`` comparison. The timings are the benchmark's to print."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow
def test_the_knee_benchmark_finds_the_same_knees_on_every_window() -> None:
    run = subprocess.run([sys.executable, "bench/knee.py", "--repeat", "1"], cwd=REPO, capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    rows = [line for line in run.stdout.splitlines() if "windows, median" in line]
    assert [r.split(":")[0].strip() for r in rows] == ["1 kHz", "100 Hz"], run.stdout
    assert all(r.endswith("same to the last bit: yes") for r in rows), run.stdout
    assert all(int(r.split(":")[1].split()[0]) >= 10 for r in rows), run.stdout  # rise windows found at each rate
    assert "analyze_signals on the 1 kHz drive" in run.stdout
