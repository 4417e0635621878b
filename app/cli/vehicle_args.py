"""The log and vehicle arguments shared by the commands that analyse a log (``analyze``, ``diagnose``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from app.cli.log_args import add_format_file, log_help

if TYPE_CHECKING:
    from app.analysis.events import EventParams
    from app.pipeline import VehicleInputs

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
    p.add_argument("--vehicle", required=True, help="driveline preset name (e.g. paper) or TOML file")
    p.add_argument("--dbc", type=Path, default=None, help="database (default: dbc/lashscope_ev.dbc)")
    p.add_argument("--signal-map", type=Path, default=None, help="signal map (default: dbc/lashscope_ev.map.toml)")
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
    """The loaded driveline with the given DBC and signal map, or the project's reference ones."""
    from app.pipeline import VehicleInputs
    from app.settings import get_settings
    from sim import load_vehicle

    dbc_dir = get_settings().dbc_dir
    return VehicleInputs(load_vehicle(args.vehicle), args.dbc or dbc_dir / "lashscope_ev.dbc",
                         args.signal_map or dbc_dir / "lashscope_ev.map.toml")
