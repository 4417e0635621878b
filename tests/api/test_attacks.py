"""The short form of ``bench/fuzz_api.py``, in CI (``--short``): the key and method attacks, the connection
attacks (header flood, slowloris, trickle uploads, forged forwarded addresses) and the legitimate load at
the default limits, fuzzed requests, stalled uploads and the work attacks (compression bombs, pathological
DBCs, drivelines and format descriptions, the signal-map proposal, the gap sensitivity and identification
jobs) against real ``lashscope serve`` processes. The figures that are not timings must meet their targets
(memory, CPU seconds, failed ``/health`` probes, files left or written outside the data directory,
responses >= 500, errors of the legitimate load); the latencies are the benchmark's to print."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow
def test_abuse_benchmark_short_form() -> None:
    run = subprocess.run([sys.executable, "bench/fuzz_api.py", "--short"], cwd=REPO, capture_output=True, text=True,
                         timeout=900)
    out = run.stdout
    assert run.returncode in (0, 1) and "Traceback" not in run.stderr, out[-3000:] + run.stderr[-3000:]

    assert "every method: answers 500 or worse (or none): 0\n" in out, out
    assert "meanwhile the right key from another address (127.0.0.2): 200\n" in out, out
    assert re.search(r"every key revoked, anonymous reads and writes: 120 requests in .*; statuses 401: 120\n", out)

    conn = {line.split()[0]: line for line in out.splitlines()
            if re.match(r"(headers|slowloris|trickle|forged forwarded) +[\d.]+ s  peak RSS ", line)}
    assert set(conn) == {"headers", "slowloris", "trickle", "forged"}, out
    for line in conn.values():
        figures = re.search(r"peak RSS +(\d+) MiB.*\(left (\d+)\).*, (\d+) failed +>=500: (\d+)", line)
        assert figures is not None, line
        rss, left, failed, errors = map(int, figures.groups())
        assert rss < 1024 and left == 0 and failed == 0 and errors == 0, line
    assert re.search(r"statuses 431: \d+$", conn["headers"]) and re.search(r"statuses 408: \d+$", conn["trickle"])
    legit = re.search(r"legitimate load: .* errors (\d+)", out)
    assert legit is not None and legit.group(1) == "0", out

    assert "responses 500 or worse (or no response): 0\n" in out, out
    assert "stalled uploads: 20, answered 408 upload_timeout: 20 " in out, out
    assert "after the abuse: files left in tmp/: 0, server handles open on tmp/: 0\n" in out, out

    rows = {line.split(" | ")[0]: line.split(" | ") for line in out.splitlines() if line.count(" | ") == 8}
    assert rows["format: backtracking regex, 5 lines (gzipped)"][1] == "422 validation_limit", out
    assert rows["format: tables nested 30 000 deep"][1] == "422 format_file", out
    assert rows["format: path names in fields and file names"][1].endswith("files named after the paths: 0"), out
    assert rows["proposal: DBC, 1100 signals in one message"][1] == "422 database_too_complex", out
    assert rows["identification, id of 300 characters"][1] == "404 identification_not_found", out
    assert rows["identification of a log without the vehicle's frames (job)"][1] == "202 -> failed missing_signal"
    worst = re.search(r"work attacks, worst: (.*)$", out, re.M)
    assert worst is not None, out
    figures = {k: float(v) for k, v in (item.rsplit(" ", 1) for item in worst.group(1).split(", "))}
    assert figures["answers >= 500"] == 0 and figures["peak RSS MiB"] < 1024, worst.group(0)
    assert figures["tmp files"] == 0 and figures["outside files"] == 0 and figures["/health failed"] == 0
    assert figures["server CPU s"] <= 10 and figures["child CPU s"] <= 10, worst.group(0)
