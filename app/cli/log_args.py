"""The log arguments every command that reads logs shares: the help line listing the formats (from
:mod:`app.log_formats`, the one list of them) and ``--format-file`` for text formats described in TOML."""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterable
from pathlib import Path

from app.log_formats import formats_sentence

FORMAT_FILE_HELP = ("TOML description of a text log format (docs/ingest-readers.md, 'Describing a format'); "
                    "logs with its shape are read with it; repeatable")


def log_help(what: str = "CAN log") -> str:
    """``CAN log: Vector BLF, Vector ASC, ... (format from content)``."""
    return f"{what}: {formats_sentence()} (format from content)"


def add_format_file(p: argparse.ArgumentParser) -> None:
    p.add_argument("--format-file", type=Path, action="append", default=None, metavar="FILE.toml",
                   help=FORMAT_FILE_HELP)


def use_format_files(paths: Iterable[Path]) -> None:
    """Validate the descriptions (FormatFileError names the file and field) and let every log this
    command opens be recognised by them, in worker processes too (through ``LASHSCOPE_FORMAT_FILES``);
    the first given wins where several fit."""
    from app.ingest.readers.described import ENV, register_format_file

    given = list(paths)
    for path in reversed(given):
        register_format_file(path)
    os.environ[ENV] = os.pathsep.join([str(p.resolve()) for p in given] + [os.environ.get(ENV, "")]).rstrip(os.pathsep)
