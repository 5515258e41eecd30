"""The cell's axes as named records: one row per axis, in the order every
step array, joint list and table of winder has them (ROS-free).

A winding cell's axes (the 2016 paper's machine):

* ``feed`` - linear: it advances the wire guide (or the rotor) one wire
  diameter per turn, ``feed_step`` metres per step;
* ``fork`` - rotary: the flyer that lays the wire, ``fork_steps_per_rev``
  steps per revolution;
* ``pole`` - rotary: it indexes the rotor from coil to coil,
  ``pole_steps_per_rev`` steps per revolution.

Every per-axis table (units in reports and exports, how a figure shows an
axis, a joint's unit in a limit) reads :data:`AXIS_TABLE`; an axis'
position in a step row is its :attr:`Axis.index`, never a literal.
"""

from __future__ import annotations

from dataclasses import dataclass

from winder.errors import BadInputError

__all__ = ["AXES", "AXIS_TABLE", "FEED", "FORK", "POLE", "Axis", "axis"]


@dataclass(frozen=True)
class Axis:
    """One axis of the cell.

    ``index``: its place in :data:`AXIS_TABLE` (a step row's column is
    ``2 + index``); ``unit``: the SI unit of its position (``m`` or ``rad``,
    as the job and sensor_msgs/JointState have them); ``rotary``: it turns
    (else it travels); ``show_scale`` and ``show_unit``: how a figure or a
    summary shows a position (a feed in mm); ``step_field``: the job field
    that sets its step; ``words``: what it is, for messages."""

    name: str
    index: int
    unit: str
    rotary: bool
    show_scale: float
    show_unit: str
    step_field: str
    words: str

    @property
    def velocity_unit(self) -> str:
        return f"{self.unit}/s"

    @property
    def acceleration_unit(self) -> str:
        return f"{self.unit}/s^2"


FEED = Axis("feed", 0, "m", False, 1e3, "mm", "feed_step", "the feed (wire guide)")
FORK = Axis("fork", 1, "rad", True, 1.0, "rad", "fork_steps_per_rev", "the flyer (fork)")
POLE = Axis("pole", 2, "rad", True, 1.0, "rad", "pole_steps_per_rev", "the pole index")
#: every axis of the cell, in its order
AXIS_TABLE: tuple[Axis, ...] = (FEED, FORK, POLE)
#: the axes' names, in order
AXES: tuple[str, ...] = tuple(a.name for a in AXIS_TABLE)


def axis(name: str) -> Axis:
    """The axis named ``name``; ValueError (one line) naming the axes if none is."""
    for a in AXIS_TABLE:
        if a.name == name:
            return a
    raise BadInputError(f"axis {name!r} is not one of {', '.join(AXES)}")
