"""Gzipped MF4: inflated to a temporary file in blocks with a size cap; a gzip bomb gets a typed error, no traceback."""

from __future__ import annotations

import gzip
import io
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from app.errors import InflatedTooLargeError
from app.ingest.frames import FrameChunk
from app.ingest.readers import _source as source_module
from app.ingest.readers import open_log
from app.tempfiles import owner_tag
from tests.conftest import REPO, sample_files

MF4 = sample_files("css-electronics-mf4", "**/*.MF4")


@pytest.fixture
def spool_dir(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Temporary files go to a folder of this test, so leftovers can be counted (asammdf keeps its own there too)."""
    d = tmp_path / "spool"
    d.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


def _bomb(inflated: int) -> bytes:
    """A small gzip member that inflates to ``inflated`` bytes starting with the MDF magic."""
    return gzip.compress(b"MDF     4.10    " + bytes(inflated - 16), compresslevel=9)


@pytest.mark.skipif(not MF4, reason="CANedge MF4 files not found (set LASHSCOPE_SHARED)")
@pytest.mark.parametrize("path", MF4, ids=lambda p: p.name)
def test_gzipped_mf4_reads_like_the_plain_file(path: Path, tmp_path: Path, spool_dir: Path) -> None:
    with open_log(path) as log:
        plain = FrameChunk.concat(list(log.chunks()))
        plain_start = log.meta.start_time
    gz = tmp_path / (path.name + ".gz")
    gz.write_bytes(gzip.compress(path.read_bytes()))
    for source in (gz, io.BytesIO(gz.read_bytes())):
        with open_log(source) as log:  # type: ignore[arg-type]
            assert log.meta.format == "mf4" and log.meta.start_time == plain_start
            assert len(list(spool_dir.glob(f"{owner_tag()}*.mf4"))) == 1  # the inflated copy, while open
            got = FrameChunk.concat(list(log.chunks()))
        assert list(spool_dir.glob(f"{owner_tag()}*.mf4")) == []  # removed on close
        assert len(got) == len(plain) > 100
        for col in ("t_ns", "arb_id", "flags", "dlc", "channel", "data"):
            assert np.array_equal(getattr(got, col), getattr(plain, col)), col


def test_gzip_bomb_stops_at_the_cap(tmp_path: Path, spool_dir: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(source_module, "MAX_INFLATED_BYTES", 1 << 20)
    bomb = tmp_path / "drive.mf4.gz"
    bomb.write_bytes(_bomb(8 << 20))
    assert bomb.stat().st_size < 20_000
    with pytest.raises(InflatedTooLargeError, match=r"drive\.mf4\.gz: decompresses to more than the 1 MiB cap") as err:
        open_log(bomb)
    assert err.value.code == "inflated_too_large" and err.value.status == 413
    assert list(spool_dir.glob(f"{owner_tag()}*.mf4")) == []  # the partial file is gone


def test_gzip_bomb_on_the_command_line(tmp_path: Path) -> None:
    bomb = tmp_path / "drive.mf4.gz"
    bomb.write_bytes(_bomb(4 << 20))
    env = {**os.environ, "LASHSCOPE_MAX_INFLATED_MB": "1", "PYTHONPATH": str(REPO)}
    dbc = REPO / "dbc" / "lashscope_ev.dbc"
    out = subprocess.run([sys.executable, "-m", "app", "decode", str(bomb), "--dbc", str(dbc)],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=120)
    assert out.returncode == 2
    assert out.stderr.strip() == ("lashscope: error [inflated_too_large]: drive.mf4.gz: decompresses to more than "
                                  "the 1 MiB cap for compressed logs (LASHSCOPE_MAX_INFLATED_MB); decompress it "
                                  "yourself or raise the cap")
    assert "Traceback" not in out.stderr
