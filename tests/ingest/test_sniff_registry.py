"""The sniffer knows a format only from its entry in the format table (app/log_formats.py)."""

from __future__ import annotations

import importlib
import re

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


def test_a_new_format_is_one_entry_in_the_table(monkeypatch: pytest.MonkeyPatch) -> None:
    head = b"#LASHTEST v1\n0.001 7E8 02 10 20\n0.002 7E8 02 10 21\n"
    with pytest.raises(UnsupportedFormatError):
        sniff.sniff_format(head, "drive.lt")
    extra = (log_formats.LogFormat("lashtest", "lashtest:LashTestReader", "test lines", (".lt",),
                                   lines=(r"^#LASHTEST v\d+$", r"^\d+\.\d+ [0-9A-F]{3} ")),
             log_formats.LogFormat("lashbin", "lashbin:LashBinReader", "test binary", magic=(b"LSHB",)))
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
