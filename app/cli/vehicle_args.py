"""The log and vehicle arguments shared by the commands that analyse a log (``analyze``, ``diagnose``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from app.pipeline import VehicleInputs


def add_log_and_vehicle(p: argparse.ArgumentParser) -> None:
    """``LOG --vehicle V [--dbc F] [--signal-map F]``."""
    p.add_argument("log", type=Path, help="CAN log (BLF, ASC, candump, TRC, SavvyCAN CSV, MF4; gzip accepted)")
    p.add_argument("--vehicle", required=True, help="driveline preset name (e.g. paper) or TOML file")
    p.add_argument("--dbc", type=Path, default=None, help="database (default: dbc/lashscope_ev.dbc)")
    p.add_argument("--signal-map", type=Path, default=None, help="signal map (default: dbc/lashscope_ev.map.toml)")


def vehicle_inputs(args: argparse.Namespace) -> VehicleInputs:
    """The loaded driveline with the given DBC and signal map, or the project's reference ones."""
    from app.pipeline import VehicleInputs
    from app.settings import get_settings
    from sim import load_vehicle

    dbc_dir = get_settings().dbc_dir
    return VehicleInputs(load_vehicle(args.vehicle), args.dbc or dbc_dir / "lashscope_ev.dbc",
                         args.signal_map or dbc_dir / "lashscope_ev.map.toml")
