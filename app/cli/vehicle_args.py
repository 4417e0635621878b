"""The log and vehicle arguments shared by the commands that analyse a log (``analyze``, ``diagnose``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from app.cli.log_args import add_format_file, log_help

if TYPE_CHECKING:
    from app.analysis.events import EventParams
    from app.pipeline import VehicleInputs
    from app.storage.records import VehicleRecord
    from sim import Vehicle

# (option, EventParams field, metavar, default, help). The defaults are repeated here so that
# registering the commands imports no numpy; tests/test_pipeline_tracking.py checks they equal EventParams'.
EVENT_OPTIONS = (
    ("--torque-band", "hysteresis_nm", "NM", 5.0, "driving above +NM, coasting within ±NM, regenerating below -NM"),
    ("--min-step", "min_step_nm", "NM", 30.0, "smallest torque step (median before vs after) that is an event"),
    ("--min-rate", "min_rate_nm_s", "NM_S", 100.0, "smallest torque rate at the crossing, in the event's direction"),
    ("--min-dwell", "min_dwell_s", "S", 0.08, "each side of a reversal must hold this long (rejects inverter ringing)"),
    ("--max-ramp-reversal", "max_ramp_reversal", "FRAC", 0.3,
     "largest share of torque travel against the event's direction at the crossing (ringing)"),
    ("--min-pedal-step", "min_pedal_step_pct", "PCT", 2.0, "the pedal must move this much the event's way"),
    ("--max-wheel-slip", "max_wheel_slip", "FRAC", 0.15, "motor vs road speed x ratio beyond this excludes the event"),
)


def add_log_and_vehicle(p: argparse.ArgumentParser) -> None:
    """``LOG --vehicle V [--dbc F] [--signal-map F]``."""
    p.add_argument("log", type=Path, help=log_help())
    add_format_file(p)
    add_vehicle(p)


def add_vehicle(p: argparse.ArgumentParser) -> None:
    """``--vehicle V [--dbc F] [--signal-map F]`` and the event thresholds."""
    p.add_argument("--vehicle", required=True,
                   help="a vehicle registered in the store (lashscope init), a preset (e.g. paper) or a driveline TOML")
    p.add_argument("--dbc", type=Path, default=None,
                   help="database (default: the registered vehicle's, else dbc/lashscope_ev.dbc)")
    p.add_argument("--signal-map", type=Path, default=None,
                   help="signal map (default: the registered vehicle's, else dbc/lashscope_ev.map.toml)")
    p.add_argument("--data-dir", type=Path, default=None,
                   help="the store registered vehicles are looked up in (default $LASHSCOPE_DATA_DIR or "
                   "./lashscope-data)")
    g = p.add_argument_group("event detection", "thresholds of tip-in/tip-out detection (docs/metrics.md)")
    for opt, name, metavar, default, text in EVENT_OPTIONS:
        g.add_argument(opt, dest=f"ev_{name}", type=float, default=None, metavar=metavar,
                       help=f"{text} (default {default:g})")


def event_params(args: argparse.Namespace, base: EventParams | None = None) -> EventParams:
    """The event thresholds given on the command line over ``base`` (the command's own defaults, e.g. the
    diagnosis' shorter post-window; ``EventParams()`` when None); InputError when out of range."""
    from dataclasses import replace

    from app.analysis.events import EventParams
    from app.errors import InputError

    given = {name: getattr(args, f"ev_{name}") for _, name, _, _, _ in EVENT_OPTIONS
             if getattr(args, f"ev_{name}", None) is not None}
    try:
        return replace(base if base is not None else EventParams(), **given)
    except ValueError as exc:
        opt = {name: o for o, name, _, _, _ in EVENT_OPTIONS}
        text = str(exc)
        for name, o in opt.items():
            text = text.replace(f"EventParams.{name}", o)
        raise InputError(f"event thresholds: {text}") from exc


def vehicle_inputs(args: argparse.Namespace) -> VehicleInputs:
    """The loaded driveline with the given DBC and signal map, or the vehicle's own (registered), or the
    project's reference ones (preset or file)."""
    return resolve_vehicle(args)[0]


def resolve_vehicle(args: argparse.Namespace) -> tuple[VehicleInputs, str]:
    """The vehicle inputs and the name to report them under (:func:`find_vehicle`); a registered vehicle
    brings its DBC and signal map, the others the project's, and ``--dbc``/``--signal-map`` override both."""
    from app.pipeline import VehicleInputs
    from app.settings import get_settings
    from app.storage.records import VehicleRecord
    from sim import load_vehicle

    found = find_vehicle(str(args.vehicle), getattr(args, "data_dir", None))
    if isinstance(found, VehicleRecord):
        return VehicleInputs(load_vehicle(found.driveline_path), args.dbc or found.database_path,
                             args.signal_map or found.signal_map_path, found.name), found.name
    dbc_dir = get_settings().dbc_dir
    vehicle = load_vehicle(found)
    return VehicleInputs(vehicle, args.dbc or dbc_dir / "lashscope_ev.dbc",
                         args.signal_map or dbc_dir / "lashscope_ev.map.toml"), \
        vehicle.name if isinstance(found, Path) else found


def load_driveline(name: str, data_dir: Path | None = None) -> Vehicle:
    """The driveline ``--vehicle`` names, for the commands that need only it (``simulate``, ``tolerance``)."""
    from app.storage.records import VehicleRecord
    from sim import load_vehicle

    found = find_vehicle(name, data_dir)
    return load_vehicle(found.driveline_path if isinstance(found, VehicleRecord) else found)


def find_vehicle(name: str, data_dir: Path | None) -> Path | VehicleRecord | str:
    """What ``--vehicle`` names, in this order: an existing driveline file (or a name ending in ``.toml``) as a
    Path, a vehicle registered in the store as its latest record, a preset as its name. Anything else is
    InputError ``vehicle_not_found`` listing the registered vehicles and the presets."""
    from app.errors import AppError
    from sim import preset_names

    path = Path(name)
    if path.suffix.lower() in (".toml", ".json") or path.is_file():
        return path
    try:
        registered, where = registered_vehicle(name, data_dir)
    except AppError:
        if name not in preset_names():
            raise
        registered, where = None, None  # a store that cannot be opened does not stand between a user and a preset
    if registered is not None:
        return registered
    if name in preset_names():
        return name
    raise vehicle_not_found(name, where)


def _store_location(data_dir: Path | None) -> tuple[str, Path] | None:
    """(store location, files) when a store exists there; None when there is none to look in (never creates one)."""
    from app.settings import Settings, get_settings

    settings = Settings(data_dir=data_dir) if data_dir is not None else get_settings()
    if settings.store_url is None and not (settings.data_dir / "lashscope.sqlite3").is_file():
        return None
    return settings.store_location, settings.data_dir


def registered_vehicle(name: str, data_dir: Path | None) -> tuple[VehicleRecord | None, list[str] | None]:
    """The latest version of ``name`` in the store (None if absent) and the names registered there
    (None when there is no store)."""
    from app.errors import NotFoundError
    from app.storage.url import open_store

    found = _store_location(data_dir)
    if found is None:
        return None, None
    store = open_store(*found)
    try:
        try:
            return store.get_vehicle(name), None
        except NotFoundError:
            return None, [v.name for v in store.list_vehicles()]
    finally:
        store.close()


def vehicle_not_found(name: str, registered: list[str] | None) -> Exception:
    """InputError ``vehicle_not_found`` naming what is registered, the presets and how to register."""
    from app.errors import InputError
    from sim import preset_names

    if registered is None:
        known = "no store with registered vehicles here (--data-dir)"
    else:
        known = "registered: " + (", ".join(registered) if registered else "none yet")
    return InputError(f"vehicle {name!r} not found; {known}; presets: {', '.join(preset_names())}; register one "
                      f"with: lashscope init LOG --dbc DBC --name {name} --preset paper", code="vehicle_not_found")
