"""CiA 402 drives over CANopen (ROS-free): the drives file (:mod:`winder.drives.config`),
the drive twin (:class:`SimulatedDrive`) and the backend that runs the cell's axes on
real drives or on twins (:class:`Cia402Backend`). Both stand on canopen and python-can:
nothing here frames a CAN message."""

from winder.drives.backend import Cia402Backend, DriveError
from winder.drives.config import DrivesConfig, DrivesFileError, load_drives, parse_drives
from winder.drives.twin import SimulatedDrive

__all__ = [
    "Cia402Backend",
    "DriveError",
    "DrivesConfig",
    "DrivesFileError",
    "SimulatedDrive",
    "load_drives",
    "parse_drives",
]
