"""Each reader module declares its format (``FORMAT = LogFormat(...)``); app/log_formats.py collects the
declarations from the modules' source without importing them."""

from __future__ import annotations

import importlib
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import pytest

import app.log_formats as log_formats
from app.ingest.readers import reader_class
from app.log_formats import LOG_FORMATS, FormatDeclarationError, discover_formats

# The table as it was written by hand in app/log_formats.py before the readers declared their formats:
# (name, "module:Class", label, suffixes, magic, lines), in its order. Formats added since sit among them.
HAND_WRITTEN = (
    ("blf", "blf:BLFReader", "Vector BLF", (".blf",), (b"LOGG",), ()),
    ("asc", "asc:ASCReader", "Vector ASC", (".asc",), (), (
        r"(?i)^\s*date\s+\S+", r"(?i)^\s*base\s+(hex|dec)\b", r"(?i)^\s*(no\s+)?internal\s+events\s+logged",
        r"(?i)^\s*begin\s+triggerblock",
        r"(?i)^\s*\d+\.\d+\s+(\d+\s+\w+x?\s+(Rx|Tx)\b|\d+\s+ErrorFrame|CANFD\s+\d+)")),
    ("candump", "candump:CandumpReader", "candump -L", (".log",), (),
     (r"^\s*\(\d+(\.\d+)?\)\s+\S+\s+[0-9A-Fa-f]{3,8}#",)),
    ("trc", "trc:TRCReader", "PEAK TRC", (".trc",), (), (
        r"^;\$(FILEVERSION|STARTTIME|COLUMNS)=", r"^\s*\d+\)\s+\d+(\.\d+)?\s+",
        r"^\s*\d+\s+\d+\.\d+\s+(DT|FD|FB|FE|BI|RR|ST|ER|EC|EV)\s")),
    ("gvret_csv", "gvret_csv:GvretCsvReader", "SavvyCAN/GVRET CSV", (".csv",), (), (
        r"(?i)^\s*Time Stamp,ID,Extended,(Dir,)?Bus,LEN",
        r"(?i)^\d+(\.\d+)?,(0x)?[0-9A-Fa-f]{1,8},(true|false),((Rx|Tx),)?\d+,\d+(,[0-9A-Fa-f]{1,2})*,?\s*$")),
    ("mf4", "mf4:MF4Reader", "MF4", (".mf4", ".mdf"), (b"MDF     ", b"UnFinMF "), ()),
    ("tcu", "tcu:TcuReader", "TCU SD-card text", (), (),
     (r"^[0-9A-Fa-f]{8}x[0-9A-Fa-f]{8}(?:[0-9A-Fa-f]{2}){0,8}\s*$",)),
    ("analyser_tsv", "analyser_tsv:AnalyserTsvReader", "USB-CAN analyser tab export", (), (), (
        r"(?i)^\ufeff?ParserFlags\tCh\tCounter\tT/R\tTime\t",
        r"(?i)^\d+\t\d+\t\d+\t(RX|TX)\t\d+(\.\d+)?\t[^\t]*\t(0x)?[0-9A-Fa-f]{1,8}\t\d+\t")),
    ("serial_dump", "serial_dump:SerialDumpReader", "serial RXn/TXn dump", (), (),
     (r"^\(\d+(\.\d+)?\)\s+[RT]X\d+\s+[0-9A-Fa-f]{1,8}\s+\[\d+\]",)),
    ("described", "described:DescribedReader", "a text format described in a TOML file", (), (), ()),
)


def test_the_declarations_give_the_hand_written_table() -> None:
    names = {row[0] for row in HAND_WRITTEN}
    got = tuple((f.name, f.reader_path, f.label, f.suffixes, f.magic, f.lines) for f in LOG_FORMATS if f.name in names)
    assert got == HAND_WRITTEN
    assert LOG_FORMATS[-1].name == "described"  # the help sentence ends "... or a text format described in ..."
    assert [f.order for f in LOG_FORMATS] == sorted({f.order for f in LOG_FORMATS})


def test_each_declaration_is_its_module_s_format_and_names_its_reader() -> None:
    for f in LOG_FORMATS:
        module = importlib.import_module(f"app.ingest.readers.{f.module}")
        assert replace(module.FORMAT, module=f.module) == f, f.name
        assert reader_class(f.name).fmt == f.name


def test_collecting_imports_no_reader() -> None:
    code = ("import sys, app.log_formats as m; assert len(m.LOG_FORMATS) >= 10; "
            "print(sorted(n for n in sys.modules if n.split('.')[0] in ('numpy', 'cantools') "
            "or n.startswith('app.ingest')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=Path(__file__).resolve().parents[2])
    assert out.stdout.strip() == "[]"


def test_collected_once_per_directory(tmp_path: Path) -> None:
    (tmp_path / "lashtest.py").write_text('FORMAT = LogFormat(name="lashtest", reader="R", label="t", order=1)\n')
    assert discover_formats(tmp_path) is discover_formats(tmp_path)
    assert discover_formats() is LOG_FORMATS


def test_a_declaration_may_name_a_string_constant_of_its_file(tmp_path: Path) -> None:
    (tmp_path / "lashtest.py").write_text(
        '"""A test reader."""\n\nfrom app.log_formats import LogFormat\n\n'
        'HEAD: str = r"^#LASHTEST v\\d+$"\n'
        'FORMAT: LogFormat = LogFormat(\n    name="lashtest", reader="LashTestReader", label="test lines",\n'
        '    suffixes=(".lt",), magic=(b"LSHT",),\n    lines=(HEAD, r"^\\d+\\.\\d+ [0-9A-F]{3} "), order=5,\n)\n'
        '# a helper module, no declaration:\n')
    (tmp_path / "lashtest_helpers.py").write_text(
        '"""No FORMAT here."""\nFORMATS = ("a",)\nFORMAT_NAMES: tuple[str, ...] = ()\n'
        'if FORMATS == ():\n    FORMAT = None\n')
    (tmp_path / "_private.py").write_text("FORMAT = broken(\n")
    (f,) = discover_formats(tmp_path)
    assert f == log_formats.LogFormat("lashtest", "LashTestReader", "test lines", (".lt",), (b"LSHT",),
                                      (r"^#LASHTEST v\d+$", r"^\d+\.\d+ [0-9A-F]{3} "), 5, "lashtest")
    assert f.reader_path == "lashtest:LashTestReader"


@pytest.mark.parametrize(("declaration", "says"), [
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1', "cannot be parsed"),
    ('FORMAT = make_format(name="x")', "LogFormat(...)"),
    ('FORMAT = LogFormat("x", "R", "x", order=1)', "keyword arguments only"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, colour="red")', "no argument 'colour'"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x")', "lacks order"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1 + 1)', "not a literal"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, lines=(re.escape("a"),))', "not a literal"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, lines=(ROW,))', "ROW, which is not"),
    ('ROW = 3\nFORMAT = LogFormat(name="x", reader="R", label="x", order=1, lines=(ROW,))', "not a string literal"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order="1")', "order= must be an integer"),
    ('FORMAT = LogFormat(name="x y", reader="R", label="x", order=1)', "name= must be an identifier"),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, suffixes=("txt",))', "suffixes="),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, magic=("LOGG",))', "magic="),
    ('FORMAT = LogFormat(name="x", reader="R", label="x", order=1, lines=r"^x")', "lines="),
    ('FORMAT = LogFormat(name="blf2", reader="R", label="x", order=10)', "order=10 is already declared by"),
    ('FORMAT = LogFormat(name="blf", reader="R", label="x", order=11)', "name='blf' is already declared by"),
])
def test_a_malformed_declaration_names_its_file(tmp_path: Path, declaration: str, says: str) -> None:
    (tmp_path / "blf.py").write_text('FORMAT = LogFormat(name="blf", reader="BLFReader", label="b", order=10)\n')
    (tmp_path / "zz_broken.py").write_text(f"import re\n\n{declaration}\n\n\nclass R:\n    pass\n")
    with pytest.raises(FormatDeclarationError) as err:
        discover_formats(tmp_path)
    assert str(tmp_path / "zz_broken.py") in str(err.value)
    assert says in str(err.value)
