"""``lashscope init LOG --dbc DBC --name NAME --preset P | --driveline FILE``: register a vehicle from a log.

Reads the log once for its message rates, proposes a signal map from the DBC's names, units and
rates among the messages the log carries, decodes the proposal and prints the evidence for each
channel (rate, unit, range, correlation, sign; :mod:`app.signal_proposal`). The user accepts it
(``--yes``, or ``y`` at the prompt when stdin is a terminal), replaces channels
(``--map ROLE=Message.Signal``, ``ROLE=-`` drops one; or ``e`` at the prompt), and the vehicle is
stored with the chosen driveline (a preset or a TOML file): the same files and checks as
``POST /vehicles``. Afterwards ``--vehicle NAME`` works in every command.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

from app.errors import InputError

if TYPE_CHECKING:
    from app.signal_proposal import Proposal

CHANNELS_HELP = ("pedal_pct, motor_torque_nm, motor_speed_rpm, vehicle_speed_kmh, wheel_speed_fl_rpm ... rr_rpm, "
                 "brake, brake_pressed, time_base")


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "init", help="register a vehicle from a log and its DBC: proposed signal map with evidence, driveline",
        description="Read LOG once for its message rates, propose a signal map from the DBC's names, units and rates "
        "among the messages the log carries, decode it and print per channel the signal, unit, rate, decoded range, "
        "correlation and sign check. Accept it (--yes, or y at the prompt on a terminal; e edits), change channels "
        "(--map ROLE=Message.Signal, ROLE=- drops one), and the vehicle is stored with the chosen driveline (a preset "
        "or a TOML file) as POST /vehicles stores it. Then --vehicle NAME works in every command.")
    p.add_argument("log", type=Path, help="a CAN log of the vehicle (any format lashscope reads)")
    p.add_argument("--dbc", type=Path, required=True, help="the vehicle's database (DBC, KCD, SYM, ARXML)")
    p.add_argument("--name", required=True, help="vehicle name: a-z, 0-9, '-', '_' (used as --vehicle NAME)")
    which = p.add_mutually_exclusive_group()
    which.add_argument("--preset", default=None, help="driveline preset (paper, single_reduction, chain_drive, ...)")
    which.add_argument("--driveline", type=Path, default=None, help="driveline TOML file (docs/simulation.md)")
    p.add_argument("--map", action="append", default=[], metavar="ROLE=Message.Signal",
                   help=f"use this signal for a channel instead of the proposal (ROLE=- drops it); repeatable. "
                   f"Roles: {CHANNELS_HELP}")
    p.add_argument("--invert", action="append", default=[], metavar="ROLE",
                   help="flip the sign of a channel (the proposal inverts a backwards motor speed or torque itself)")
    p.add_argument("--no-invert", action="append", default=[], metavar="ROLE",
                   help="keep a channel's sign as the DBC gives it, whatever the sign check proposes")
    p.add_argument("--yes", "-y", action="store_true", help="accept the proposal without asking")
    p.add_argument("--save-map", type=Path, default=None, metavar="TOML", help="also write the signal map here")
    p.add_argument("--data-dir", type=Path, default=None, help="the store (default $LASHSCOPE_DATA_DIR or "
                   "./lashscope-data)")
    p.add_argument("--store", default=None, help="the store as a URL instead (sqlite:///..., postgresql://...)")
    p.add_argument("--strict", action="store_true", help="no DBC repairs; stop at the first damaged log record")
    p.set_defaults(func=run)


def _check_args(args: argparse.Namespace) -> dict[str, bool]:
    """Everything that can be refused before the log is read; the fixed signs."""
    from app.ingest.signalmap import CANONICAL
    from app.signal_proposal import parse_overrides
    from app.storage.sqlstore import check_vehicle_name
    from sim import preset_names

    check_vehicle_name(args.name)
    if not args.log.is_file():
        raise InputError(f"log {args.log} not found", code="file_not_found")
    if not args.dbc.is_file():
        raise InputError(f"database {args.dbc} not found", code="file_not_found")
    if args.driveline is not None and not args.driveline.is_file():
        raise InputError(f"--driveline {args.driveline} not found", code="file_not_found")
    if args.preset is not None and args.preset not in preset_names():
        raise InputError(f"--preset {args.preset!r}: presets are {', '.join(preset_names())}", code="unknown_preset")
    parse_overrides(args.map)
    fixed: dict[str, bool] = {}
    for flag, items, value in (("--invert", args.invert, True), ("--no-invert", args.no_invert, False)):
        for role in items:
            if role not in CANONICAL:
                raise InputError(f"{flag} {role!r}: not a channel; channels are {', '.join(CANONICAL)}",
                                 code="invalid_map_override")
            if fixed.get(role, value) != value:
                raise InputError(f"{role}: both --invert and --no-invert", code="invalid_map_override")
            fixed[role] = value
    return fixed


def _interactive() -> bool:
    return sys.stdin.isatty()


def _ask(prompt: str) -> str:
    try:
        return input(prompt).strip()
    except EOFError:
        return "n"


def _edit(overrides: dict[str, str | None], fixed: dict[str, bool], database: Path) -> None:
    """Read ``ROLE=Message.Signal`` / ``ROLE=-`` / ``invert ROLE`` lines until an empty one; each is checked
    against the database as it is typed."""
    from app.errors import AppError
    from app.ingest.database import load_database
    from app.signal_proposal import check_source, parse_overrides

    loaded = load_database(database)

    print("one change a line: ROLE=Message.Signal, ROLE=- (drop), invert ROLE, keep ROLE (undo invert); "
          "an empty line shows the new proposal")
    while True:
        line = _ask("> ")
        if not line or line == "n":
            return
        word, _, role = line.partition(" ")
        try:
            if word in ("invert", "keep") and role.strip():
                _check_role(role.strip())
                fixed[role.strip()] = word == "invert"
            else:
                change = parse_overrides([line])
                for role, source in change.items():
                    if source is not None:
                        check_source(loaded, role, source)
                overrides.update(change)
        except AppError as exc:
            print(f"  {exc}")


def _check_role(role: str) -> None:
    from app.ingest.signalmap import CANONICAL

    if role not in CANONICAL:
        raise InputError(f"{role!r} is not a channel; channels are {', '.join(CANONICAL)}")


def _driveline(args: argparse.Namespace) -> None:
    """Ask for a preset or a file when neither was given (a terminal only)."""
    from sim import preset_names

    if args.preset is not None or args.driveline is not None:
        return
    if not (_interactive() and not args.yes):
        raise InputError(f"give the driveline: --preset ({', '.join(preset_names())}) or --driveline FILE.toml",
                         code="driveline_required")
    while True:
        answer = _ask(f"driveline: a preset ({', '.join(preset_names())}) or a TOML file: ")
        if answer in preset_names():
            args.preset = answer
            return
        if answer and Path(answer).is_file():
            args.driveline = Path(answer)
            return
        if answer in ("", "n"):
            raise InputError("no driveline chosen", code="driveline_required")
        print(f"  {answer!r} is neither a preset nor a file")


def choose(args: argparse.Namespace, fixed: dict[str, bool]) -> Proposal:
    """The proposal the user accepts (``--yes``, or the prompt); InputError when it is not accepted."""
    from app.signal_proposal import parse_overrides, proposal_table, propose

    overrides = parse_overrides(args.map)
    while True:
        proposal = propose(args.log, args.dbc, overrides, invert=fixed, strict=args.strict)
        print(proposal_table(proposal), flush=True)
        if args.yes:
            return proposal
        if not _interactive():
            raise InputError("the proposed signal map is not confirmed: run again with --yes to accept it, with "
                             "--map ROLE=Message.Signal to change a channel, or from a terminal to be asked",
                             code="confirmation_required")
        answer = _ask("accept this signal map? [y]es / [e]dit / [n]o: ").lower()
        if answer in ("y", "yes"):
            return proposal
        if answer in ("e", "edit"):
            _edit(overrides, fixed, args.dbc)
            continue
        raise InputError("signal map not accepted; nothing registered", code="not_confirmed")


def run(args: argparse.Namespace) -> int:
    from app.pipeline import check_vehicle_files
    from app.settings import Settings
    from app.storage.url import open_store
    from sim import dump_toml, load_vehicle

    fixed = _check_args(args)
    proposal = choose(args, fixed)
    if proposal.missing:
        from app.errors import SignalMapError

        named = {ch: ", ".join(f"{c.message}.{c.signal}" for c in proposal.candidates.get(ch, [])) or "none"
                 for ch in proposal.missing}
        hint = "; ".join(f"{ch}: {names}" for ch, names in named.items())
        raise SignalMapError(f"no signal found for {', '.join(proposal.missing)}, which every analysis needs "
                             f"(candidates by name: {hint}); give --map ROLE=Message.Signal")
    _driveline(args)
    smap = proposal.smap
    smap.name = args.name
    text = smap.to_toml()
    with tempfile.TemporaryDirectory(prefix="lashscope-init-") as tmp:
        map_path = Path(tmp) / "signals.map.toml"
        map_path.write_text(text, encoding="utf-8")
        if args.driveline is not None:
            driveline = args.driveline
        else:
            driveline = Path(tmp) / "driveline.toml"
            driveline.write_text(dump_toml(load_vehicle(args.preset)), encoding="utf-8")
        summary = check_vehicle_files(driveline, args.dbc, map_path)
        overrides = {k: v for k, v in (("data_dir", args.data_dir), ("store_url", args.store)) if v is not None}
        settings = Settings(**overrides)
        store = open_store(settings.store_location, files=settings.data_dir)
        try:
            rec, created = store.add_vehicle(args.name, driveline=driveline, database=args.dbc, signal_map=map_path,
                                             summary=summary)
        finally:
            store.close()
    if args.save_map is not None:
        args.save_map.write_text(text, encoding="utf-8")
        print(f"signal map written to {args.save_map}")
    what = "registered" if created else "unchanged (same files as the latest version)"
    source = f"preset {args.preset}" if args.driveline is None else str(args.driveline)
    print(f"vehicle {rec.name} v{rec.version} {what}: driveline {source}, database {args.dbc.name}, "
          f"{len(smap.channels)} channels; store {settings.store_location}")
    where = "" if args.data_dir is None and args.store is None else \
        (f" --data-dir {args.data_dir}" if args.data_dir is not None else "")
    print(f"next: lashscope analyze {args.log} --vehicle {rec.name}{where}")
    return 0
