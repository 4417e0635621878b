"""Every gzipped log inflates to a cap decided before reading: a compression bomb of any format is
refused with 413 ``inflated_too_large`` after a bounded amount of work, naming the limit."""

from __future__ import annotations

import gzip
from pathlib import Path

import pytest

from app.errors import InflatedTooLargeError
from app.ingest.readers import _source, open_log
from app.pipeline import inspect_log

INFLATED = 48 * 2**20  # past the 32 MiB floor a small file may always inflate to

LINES = {
    "candump": b"(1609459200.000000) can0 123#0011223344556677\n",
    "asc": b"   0.000000 1  123             Rx   d 8 00 11 22 33 44 55 66 77\n",
    "trc": b"     1)         0.0  Rx         0123  8  00 11 22 33 44 55 66 77 \n",
}


def bomb(path: Path, head: bytes, line: bytes) -> Path:
    with gzip.open(path, "wb", compresslevel=9) as f:
        f.write(head)
        block = line * (2**20 // len(line))
        for _ in range(INFLATED // len(block) + 1):
            f.write(block)
    return path


@pytest.mark.parametrize("fmt", sorted(LINES))
def test_text_bombs_stop_at_the_ratio_cap(fmt: str, tmp_path: Path) -> None:
    head = b"date Fri Jan 1 00:00:00.000 am 2021\nbase hex  timestamps absolute\n" if fmt == "asc" else b""
    path = bomb(tmp_path / f"drive.{fmt}.gz", head, LINES[fmt])
    assert path.stat().st_size * _source.MAX_INFLATE_RATIO < _source.MIN_INFLATED_BYTES
    with pytest.raises(InflatedTooLargeError) as err:
        inspect_log(path)
    assert err.value.status == 413 and err.value.code == "inflated_too_large"
    assert str(err.value) == (f"drive.{fmt}.gz: decompresses to more than the 32 MiB cap for compressed logs "
                              "(32x its compressed size); decompress it yourself or raise the cap")


def test_mf4_bomb_names_the_ratio_and_a_plain_log_inflates_freely(tmp_path: Path) -> None:
    path = bomb(tmp_path / "drive.mf4.gz", b"MDF     4.10    ", bytes(4096))
    with pytest.raises(InflatedTooLargeError, match=r"32 MiB cap for compressed logs \(32x its compressed size\)"):
        open_log(path)
    plain = tmp_path / "drive.log.gz"
    plain.write_bytes(gzip.compress(LINES["candump"] * 1000))
    assert inspect_log(plain)["frames"] == 1000


def test_the_cap_is_the_smaller_of_the_setting_and_the_ratio(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_source, "MAX_INFLATED_BYTES", 100 * 2**20)
    assert _source.inflate_cap(None) == (100 * 2**20, "LASHSCOPE_MAX_INFLATED_MB")
    assert _source.inflate_cap(2**20) == (32 * 2**20, "32x its compressed size")
    assert _source.inflate_cap(2 * 2**20) == (64 * 2**20, "32x its compressed size")
    assert _source.inflate_cap(10 * 2**20) == (100 * 2**20, "LASHSCOPE_MAX_INFLATED_MB")
