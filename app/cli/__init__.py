"""The ``lashscope`` command line.

Each subcommand lives in its own module under ``app.cli`` exposing
``register(subparsers)`` which adds a parser whose ``func`` attribute takes the parsed
namespace and returns an exit code. The dispatcher maps :class:`app.errors.AppError`
and :class:`sim.errors.SimError` to a one-line message and exit code 2, so no
traceback reaches a user. ``register()`` must stay cheap: command modules import their
heavy dependencies (fastapi, uvicorn, the numba-backed simulator, matplotlib, pandas)
inside the command function, since every invocation registers every command.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from app.cli.log_args import use_format_files
from app.errors import AppError

# Subcommand modules, in the order they appear in --help.
COMMANDS: tuple[str, ...] = ("decode", "sim", "serve", "keys", "analyze", "identify", "diagnose", "batch", "fleet",
                             "demo", "replay", "live", "init", "ratings", "vehicles")


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


def _sim_error() -> type[Exception]:
    """``sim.errors.SimError`` if the simulator was imported (it raised it then), else a type nothing raises.

    Importing ``sim.errors`` imports the ``sim`` package and with it numba (~0.4 s): a command
    that never simulates (``--help``, ``serve``, ``decode``) should not pay for it.
    """
    module = sys.modules.get("sim.errors")
    return getattr(module, "SimError", _NeverRaised) if module is not None else _NeverRaised


class _NeverRaised(Exception):
    pass


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        if getattr(args, "format_file", None):  # text formats described in TOML
            use_format_files(args.format_file)
        code = args.func(args)
    except Exception as exc:
        if not isinstance(exc, AppError | _sim_error()):
            raise
        err_code = getattr(exc, "code", "error")
        print(f"lashscope: error [{err_code}]: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("lashscope: interrupted", file=sys.stderr)
        return 130
    return int(code or 0)


if __name__ == "__main__":
    raise SystemExit(main())
