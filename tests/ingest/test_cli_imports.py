"""Start-up stays cheap: decode/replay/live/sim/report import their heavy libraries lazily, reading a log does not
load the simulator, and a bounded child proposing a signal map does not load ``scipy.signal``."""

from __future__ import annotations

import subprocess
import sys

import pytest

from tests.conftest import REPO, sample_files

HEAVY = ("cantools", "can", "pyarrow", "scipy", "asammdf", "pandas", "fastapi", "numba", "numpy")


def test_registering_commands_imports_no_heavy_library() -> None:
    code = (
        "import argparse, sys\n"
        "import app.cli\n"
        "before = set(sys.modules)\n"  # what the dispatcher package itself imports is not these modules' doing
        "from app.cli import decode, live, replay, report, sim\n"
        "sub = argparse.ArgumentParser().add_subparsers()\n"
        "for m in (decode, live, replay, sim):\n"
        "    m.register(sub)\n"
        f"print(','.join(m for m in {HEAVY!r} if m in sys.modules and m not in before))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""  # none of them was imported


def test_help_still_lists_the_interfaces() -> None:
    code = "from app.cli import main; main(['replay', '--help'])"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "tcp_loopback" in out.stdout


def test_top_level_help_imports_no_heavy_library_nor_the_simulator() -> None:
    """``lashscope --help`` builds every command's parser; none may import numba, numpy or the simulator."""
    code = (
        "import sys\n"
        "from app.cli import main\n"
        "try:\n"
        "    main(['--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        f"print(','.join(m for m in {(*HEAVY, 'sim', 'matplotlib')!r} if m in sys.modules), file=sys.stderr)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and "diagnose" in out.stdout
    assert out.stderr.strip() == ""


def test_reading_asc_and_mf4_loads_neither_numba_nor_asammdf() -> None:
    """The ASC scanner is numpy only and the MF4 reader reads CANedge files itself."""
    mf4 = sample_files("css-electronics-mf4", "**/*.MF4")
    asc = [p for p in sample_files("", "**/*.asc") if p.stat().st_size > 8192][:1]
    if not (mf4 and asc):
        pytest.skip("shared data not found (set LASHSCOPE_SHARED)")
    code = (
        "import sys\n"
        "from app.ingest.readers import open_log\n"
        f"for path in {[str(mf4[0]), str(asc[0])]!r}:\n"
        "    with open_log(path) as log:\n"
        "        assert sum(len(c) for c in log.chunks()) > 0\n"
        "print(','.join(m for m in ('numba', 'asammdf', 'can') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


def test_reading_a_log_loads_neither_the_simulator_nor_numba() -> None:
    """app.ingest keeps its own copy of 1 rad/s in rpm (tests/ingest/test_signalmap.py holds it to the simulator's) so
    that a process that only reads a log never loads the simulator and numba."""
    code = "import sys, app.ingest.pipeline_signals; print('sim' in sys.modules, 'numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["False", "False"]


def test_the_proposal_child_does_not_import_scipy_signal() -> None:
    """A bounded child (app.bounded) imports its target afresh, and that import is CPU the client's request costs:
    ``scipy.signal`` alone is about a second (scipy 1.17), paid six times by six proposals at once. Nothing a
    signal-map proposal runs filters a signal, so the simulator imports it where the seat filter needs it."""
    code = ("import sys, app.signal_proposal; "
            "print(sorted(m for m in ('scipy.signal', 'scipy.stats') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_the_upload_check_child_reads_the_log_and_nothing_else() -> None:
    """``POST /logs`` with a text layout checks the upload in a bounded child (``app.ingest.inspect:inspect_log``),
    which imports its target afresh: the analysis (scipy.signal), the simulator and numba were about two seconds of
    that child's CPU when the check lived in app.pipeline, for a function that only reads the log."""
    code = ("import sys, app.ingest.inspect; "
            "print(sorted(m for m in ('app.analysis', 'app.pipeline', 'sim', 'numba', 'scipy.signal') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"
