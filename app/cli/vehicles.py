"""``lashscope vehicles list|show|compare``: the vehicles a store holds, and what moved between two of them.

A vehicle is named as ``--vehicle`` names it -- a driveline TOML, a vehicle registered in the store
(``NAME`` for its latest version, ``NAME@VERSION`` for another), or a preset -- so an identified file
compares with the file it came from before it is registered::

    lashscope vehicles compare my-ev.toml my-ev_identified.toml
    lashscope vehicles compare ev@1 ev@2
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from app.storage.base import Store


def register(sub: Any) -> None:
    p: argparse.ArgumentParser = sub.add_parser(
        "vehicles", help="list the registered vehicles; show one; compare two (what an identification moved)",
        description="The vehicles of a store, and two vehicle files side by side: torsional stiffness at the motor, "
        "first mode and damping ratio, mass, total lash, torque gain; each identified file's provenance; every "
        "driveline field that differs. A vehicle is a driveline TOML, a registered NAME or NAME@VERSION, or a preset.")
    where = argparse.ArgumentParser(add_help=False)
    where.add_argument("--data-dir", type=Path, default=None,
                       help="the store registered vehicles are looked up in (default $LASHSCOPE_DATA_DIR or "
                       "./lashscope-data)")
    where.add_argument("--json", action="store_true", help="print JSON instead of text")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    actions.required = True
    actions.add_parser("list", parents=[where], help="registered vehicles with their versions")
    show = actions.add_parser("show", parents=[where], help="one vehicle's figures (and provenance, if identified)")
    show.add_argument("vehicle", help="driveline TOML, NAME[@VERSION] or preset")
    cmp = actions.add_parser("compare", parents=[where], help="two vehicles side by side: what moved")
    cmp.add_argument("a", help="driveline TOML, NAME[@VERSION] or preset (e.g. the file a car was identified from)")
    cmp.add_argument("b", help="the other one (e.g. the identified file)")
    cmp.add_argument("--all", action="store_true", help="list every driveline field, not only those that differ")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.action == "list":
        return _list(args)
    from app.vehicle_compare import compare_texts, comparison_lines, describe_text, description_lines

    if args.action == "show":
        desc = describe_text(*reversed(vehicle_text(args.vehicle, args.data_dir)))
        print(json.dumps(desc, indent=2) if args.json else "\n".join(description_lines(desc)))
        return 0
    (la, ta), (lb, tb) = vehicle_text(args.a, args.data_dir), vehicle_text(args.b, args.data_dir)
    cmp = compare_texts(ta, tb, la, lb)
    print(json.dumps(cmp.to_dict(), indent=2) if args.json else "\n".join(comparison_lines(cmp, args.all)))
    return 0


def vehicle_text(ref: str, data_dir: Path | None) -> tuple[str, str]:
    """(label, driveline TOML text) of what ``ref`` names: a file, ``NAME[@VERSION]`` in the store, or a preset.

    InputError ``vehicle_not_found`` (as ``--vehicle``) or ``not_found`` for a version the store lacks."""
    from app.cli.vehicle_args import find_vehicle
    from app.errors import InputError
    from app.storage.records import VehicleRecord
    from sim import dump_toml, load_vehicle

    name, at, version = ref.rpartition("@") if "@" in ref and not Path(ref).is_file() else (ref, "", "")
    if at:
        if not version.isdigit() or not 0 < int(version) < 2**62:
            raise InputError(f"{ref!r}: the version after @ must be a whole number >= 1", code="invalid_parameter")
        store = _open(data_dir, ref)
        try:
            rec = store.get_vehicle(name, int(version))
        finally:
            store.close()
        return f"{rec.name} version {rec.version} (registered {rec.created_at})", _read(rec.driveline_path, ref)
    found = find_vehicle(name, data_dir)
    if isinstance(found, VehicleRecord):
        return (f"{found.name} version {found.version} (registered {found.created_at}, the latest)",
                _read(found.driveline_path, ref))
    if isinstance(found, Path):
        if not found.is_file():
            raise InputError(f"vehicle file {found} does not exist", code="vehicle_not_found")
        return str(found), _read(found, ref)
    return f"{found} (preset)", dump_toml(load_vehicle(found))


def _read(path: Path, ref: str) -> str:
    from app.errors import InputError

    try:
        return path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{ref}: cannot read {path}: {exc}", code="invalid_vehicle") from exc


def _open(data_dir: Path | None, ref: str) -> Store:
    from app.cli.vehicle_args import _store_location
    from app.errors import InputError
    from app.storage.url import open_store

    found = _store_location(data_dir)
    if found is None:
        raise InputError(f"{ref}: no store with registered vehicles here (--data-dir)", code="vehicle_not_found")
    return open_store(*found)


def _list(args: argparse.Namespace) -> int:
    store = _open(args.data_dir, "vehicles list")
    try:
        rows = [(v.name, [(r.version, r.created_at) for r in store.vehicle_versions(v.name)])
                for v in store.list_vehicles()]
    finally:
        store.close()
    if args.json:
        print(json.dumps([{"name": n, "versions": [{"version": v, "created_at": c} for v, c in vs]}
                          for n, vs in rows], indent=2))
    elif not rows:
        print("no vehicles registered yet (lashscope init LOG --dbc DBC --name NAME)")
    for name, versions in [] if args.json else rows:
        print(f"{name}: {len(versions)} version(s), latest {versions[-1][0]} ({versions[-1][1]})")
    return 0
