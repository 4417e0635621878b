"""Temporary files are tagged with their writer and swept once it is gone, or by age."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from app.tempfiles import owner_tag, sweep, temp_dir_of


def ended_process_tag() -> str:
    """The tag a process that has exited wrote its files with."""
    proc = subprocess.run([sys.executable, "-c", "from app.tempfiles import owner_tag; print(owner_tag())"],
                          capture_output=True, text=True, check=True, env={**os.environ, "PYTHONPATH": os.getcwd()})
    return proc.stdout.strip()


def test_a_gone_writers_files_go_at_once_a_live_ones_by_age(tmp_path: Path) -> None:
    gone = tmp_path / f"{ended_process_tag()}partial.blf"
    gone.write_bytes(b"cut off by kill -9")
    folder = tmp_path / f"{ended_process_tag()}spool"
    folder.mkdir()
    (folder / "part").write_bytes(b"x")
    mine_old, mine_new = tmp_path / f"{owner_tag()}old.mf4", tmp_path / f"{owner_tag()}new.mf4"
    for p in (mine_old, mine_new):
        p.write_bytes(b"inflating")
    os.utime(mine_old, (time.time() - 600, time.time() - 600))
    assert sweep(tmp_path, float("inf")) == 2  # writer gone: whatever the age
    assert not gone.exists() and not folder.exists() and mine_old.exists()
    assert sweep(tmp_path, 120.0) == 1  # not written to for 10 minutes
    assert not mine_old.exists() and mine_new.exists()
    assert sweep(tmp_path) == 1 and list(tmp_path.iterdir()) == []


def test_a_process_id_used_again_is_not_the_writer(tmp_path: Path) -> None:
    host, pid, _started, _ = owner_tag().split("-", 3)
    reused = tmp_path / f"{host}-{pid}-1-earlier.blf"  # this pid, but a process that started at tick 1
    other_host = tmp_path / f"00000000-{pid}-1-elsewhere.blf"  # another machine's writer: by age only
    untagged = tmp_path / "0f3a.blf"
    for p in (reused, other_host, untagged):
        p.write_bytes(b"x")
    assert sweep(tmp_path, 120.0) == 1 and not reused.exists()


def test_temp_dir_of_sends_every_temporary_file_to_the_data_directory(tmp_path: Path) -> None:
    before = tempfile.gettempdir()
    with temp_dir_of(tmp_path) as d:
        assert d == tmp_path / "tmp" and tempfile.gettempdir() == str(d)
        with tempfile.NamedTemporaryFile() as fh:
            assert Path(fh.name).parent == d
    assert tempfile.gettempdir() == before
