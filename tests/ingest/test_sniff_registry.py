"""The sniffer knows a format only from its declaration (``FORMAT`` of its reader module, collected by
app/log_formats.py)."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

import app.log_formats as log_formats
from app.errors import UnsupportedFormatError
from app.ingest.readers import sniff


def test_every_sniffed_format_says_how_it_is_known() -> None:
    for f in log_formats.LOG_FORMATS:
        if f.name in log_formats.SNIFFED:
            assert f.magic or f.lines, f"{f.name}: neither magic bytes nor line shapes"
        for p in f.lines:
            re.compile(p)


def test_a_new_format_is_one_declaration(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    head = b"#LASHTEST v1\n0.001 7E8 02 10 20\n0.002 7E8 02 10 21\n"
    with pytest.raises(UnsupportedFormatError):
        sniff.sniff_format(head, "drive.lt")
    (tmp_path / "lashtest.py").write_text(
        'FORMAT = LogFormat(name="lashtest", reader="LashTestReader", label="test lines", order=95,\n'
        '                   suffixes=(".lt",), lines=(r"^#LASHTEST v\\d+$", r"^\\d+\\.\\d+ [0-9A-F]{3} "))\n')
    (tmp_path / "lashbin.py").write_text(
        'FORMAT = LogFormat(name="lashbin", reader="LashBinReader", label="test binary", order=96, magic=(b"LSHB",))\n')
    extra = log_formats.discover_formats(tmp_path)
    assert [f.name for f in extra] == ["lashtest", "lashbin"]
    monkeypatch.setattr(log_formats, "LOG_FORMATS", (*log_formats.LOG_FORMATS, *extra))
    try:
        fresh = importlib.reload(sniff)
        assert fresh.sniff_format(head, "drive.lt") == "lashtest"
        assert fresh.sniff_format(b"LSHB\x00\x01rest", None) == "lashbin"
        # the formats already there are still told apart as before
        assert fresh.sniff_format(b"LOGG" + bytes(140), "x.blf") == "blf"
        assert fresh.sniff_format(b"(1.5) can0 123#DEADBEEF\n" * 3, "x.log") == "candump"
    finally:
        monkeypatch.undo()
        importlib.reload(sniff)
