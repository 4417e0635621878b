"""The ``lashscope`` command line.

Each subcommand lives in its own module under ``app.cli`` exposing
``register(subparsers)`` which adds a parser whose ``func`` attribute takes the parsed
namespace and returns an exit code. The dispatcher maps :class:`app.errors.AppError`
and :class:`sim.errors.SimError` to a one-line message and exit code 2, so no
traceback reaches a user.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from app.errors import AppError
from sim.errors import SimError

# Subcommand modules, in the order they appear in --help.
COMMANDS: tuple[str, ...] = ("decode", "sim", "serve", "analyze", "diagnose", "demo", "replay", "live")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lashscope",
        description="EV driveline shuffle and clunk from CAN logs: ingest, simulate, compare, diagnose.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name in COMMANDS:
        module = importlib.import_module(f"app.cli.{name}")
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        code = args.func(args)
    except (AppError, SimError) as exc:
        err_code = getattr(exc, "code", "error")
        print(f"lashscope: error [{err_code}]: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lashscope: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    raise SystemExit(main())
