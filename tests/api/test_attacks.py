"""The short form of ``bench/fuzz_api.py``'s connection attacks, in CI: header flood, slowloris,
trickle uploads and forged forwarded addresses against a real ``lashscope serve``, then the
legitimate load at the default limits. The figures that are not timings must meet their targets
(memory, failed ``/health`` probes, files left, responses >= 500, errors of the legitimate load);
the latencies are the benchmark's to print."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow
def test_connection_attacks_short_form() -> None:
    run = subprocess.run([sys.executable, "bench/fuzz_api.py", "--conn-only", "--conn-scale", "0.05"], cwd=REPO,
                         capture_output=True, text=True, timeout=900)
    out = run.stdout
    assert run.returncode in (0, 1) and "Traceback" not in run.stderr, out[-3000:] + run.stderr[-3000:]
    lines = {line.split()[0]: line for line in out.splitlines() if " peak RSS " in line}
    assert set(lines) == {"headers", "slowloris", "trickle", "forged"}, out
    for line in lines.values():
        figures = re.search(r"peak RSS +(\d+) MiB.*\(left (\d+)\).*, (\d+) failed +>=500: (\d+)", line)
        assert figures is not None, line
        rss, left, failed, errors = map(int, figures.groups())
        assert rss < 1024 and left == 0 and failed == 0 and errors == 0, line
    assert re.search(r"statuses 431: \d+$", lines["headers"]) and re.search(r"statuses 408: \d+$", lines["trickle"])
    legit = re.search(r"legitimate load: .* errors (\d+)", out)
    assert legit is not None and legit.group(1) == "0", out
