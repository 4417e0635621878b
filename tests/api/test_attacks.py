"""The short form of ``bench/fuzz_api.py``'s connection attacks, in CI: header flood, slowloris,
trickle uploads and forged forwarded addresses against a real ``lashscope serve``, then the
legitimate load at the default limits; every target the benchmark prints must hold."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import REPO


@pytest.mark.slow
def test_connection_attacks_short_form() -> None:
    run = subprocess.run([sys.executable, "bench/fuzz_api.py", "--conn-only", "--conn-scale", "0.05"], cwd=REPO,
                         capture_output=True, text=True, timeout=900)
    out = run.stdout
    assert run.returncode == 0, out[-3000:] + run.stderr[-3000:]
    assert "connection targets: all met" in out
    lines = {line.split()[0]: line for line in out.splitlines() if " peak RSS " in line}
    assert set(lines) == {"headers", "slowloris", "trickle", "forged"}
    assert "431: " in lines["headers"] and "408: " in lines["trickle"]
    assert "(left 0)" in lines["trickle"] and ">=500: 0" in lines["trickle"]
