"""CiA 402 drives over CANopen (ROS-free): the drives file (:mod:`winder.drives.config`),
the drive twin (:class:`SimulatedDrive`) and the backend that runs the cell's axes on
real drives or on twins (:class:`Cia402Backend`). Both stand on canopen and python-can:
nothing here frames a CAN message.

The names below are loaded when first used, so that importing the drives file's
module (:mod:`winder.drives.config`, which a node's ``--help`` reads) does not load
canopen. :data:`EXAMPLES` is the directory of the example drives files installed with
the package (docs/DRIVES.md)."""

from __future__ import annotations

import importlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from winder.drives.backend import Cia402Backend, DriveError
    from winder.drives.config import DrivesConfig, DrivesFileError, load_drives, parse_drives
    from winder.drives.twin import SimulatedDrive

__all__ = [
    "EXAMPLES",
    "Cia402Backend",
    "DriveError",
    "DrivesConfig",
    "DrivesFileError",
    "SimulatedDrive",
    "load_drives",
    "parse_drives",
]

#: the example drives files, package data: ``twin.yaml`` (the cell on drive twins) and
#: ``example_socketcan.yaml`` (a real cell on can0, its EDS lines to replace)
EXAMPLES = Path(__file__).with_name("examples")

#: each public name and the module that defines it
_WHERE = {
    "Cia402Backend": "backend",
    "DriveError": "backend",
    "DrivesConfig": "config",
    "DrivesFileError": "config",
    "load_drives": "config",
    "parse_drives": "config",
    "SimulatedDrive": "twin",
}


def __getattr__(name: str) -> Any:
    module = _WHERE.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{module}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted([*globals(), *_WHERE])
