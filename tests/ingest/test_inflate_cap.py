"""Every gzipped log inflates to a cap decided before reading: a compression bomb is refused with
413 ``inflated_too_large`` after a bounded amount of work, naming the limit (the text formats over
HTTP: tests/api/test_work_limits.py)."""

from __future__ import annotations

import gzip
import os
import sys
from pathlib import Path

import pytest

from app.errors import InflatedTooLargeError
from app.ingest.inspect import inspect_log
from app.ingest.readers import _source, open_log
from tests.api.attacks import BOMB_LINES, gzip_bomb

INFLATED = 48 * 2**20  # past the 32 MiB floor a small file may always inflate to


def test_mf4_bomb_names_the_ratio_and_a_plain_log_inflates_freely(tmp_path: Path) -> None:
    path = tmp_path / "drive.mf4.gz"
    path.write_bytes(gzip_bomb("mf4", INFLATED))
    with pytest.raises(InflatedTooLargeError, match=r"32 MiB cap for compressed logs \(32x its compressed size\)"):
        open_log(path)
    plain = tmp_path / "drive.log.gz"
    plain.write_bytes(gzip.compress(BOMB_LINES["candump"] * 1000))
    assert inspect_log(plain)["frames"] == 1000


def test_the_cap_is_the_smaller_of_the_setting_and_the_ratio(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_source, "MAX_INFLATED_BYTES", 100 * 2**20)
    assert _source.inflate_cap(None) == (100 * 2**20, "LASHSCOPE_MAX_INFLATED_MB")
    assert _source.inflate_cap(2**20) == (32 * 2**20, "32x its compressed size")
    assert _source.inflate_cap(2 * 2**20) == (64 * 2**20, "32x its compressed size")
    assert _source.inflate_cap(10 * 2**20) == (100 * 2**20, "LASHSCOPE_MAX_INFLATED_MB")


@pytest.mark.parametrize("value", [None, "1", "0.5", "4096", "12.25", "0", "-3", "abc", " 7", "1e3", "inf"])
def test_the_cap_read_without_the_settings_is_the_settings_cap(value: str | None,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    """A command-line run reads LASHSCOPE_MAX_INFLATED_MB without loading the settings, with their answer."""
    from app.settings import Settings

    for key in [k for k in os.environ if k.lower() == "lashscope_max_inflated_mb"]:
        monkeypatch.delenv(key)
    if value is not None:
        monkeypatch.setenv("LASHSCOPE_MAX_INFLATED_MB", value)
    try:
        expected: float | type[Exception] = Settings().max_inflated_mb
    except Exception as exc:  # a bad value: the settings' own error
        expected = type(exc)
    monkeypatch.delitem(sys.modules, "app.settings")  # as in a fresh command-line process
    if isinstance(expected, float):
        assert _source._max_inflated_mb() == expected
    else:
        with pytest.raises(expected):
            _source._max_inflated_mb()
    plain = value is None or value in ("1", "0.5", "4096", "12.25")
    assert ("app.settings" not in sys.modules) == plain  # read directly only where it is a plain number
