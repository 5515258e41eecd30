"""What the ``winder`` console script keeps for a command beyond its return:
the cell container started before the command read its arguments
(:mod:`winder.ros.early`), which ``winder run`` takes, and whether the
command's DDS participant is gone, so that the process may leave at once.

Below :mod:`winder.cli.commands` and the console script
(:func:`winder.cli.main`), which both use it. Plain Python: no ROS."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from winder.ros.early import EarlyContainer

__all__ = ["early_containers", "leave_when_done", "ros_done", "take_early"]

#: set by a command that ran ROS and has destroyed every node it made
ros_done: list[bool] = []
#: the cell container started before the command read its arguments (winder.ros.early)
early_containers: list[EarlyContainer] = []


def take_early() -> EarlyContainer | None:
    """The container :func:`winder.ros.early.prestart` started for this
    command, if any, now the caller's to hand arguments to or stop."""
    return early_containers.pop() if early_containers else None


def leave_when_done() -> None:
    """Say that this command's DDS participant is gone (its nodes destroyed,
    rclpy shut down): once it returns, the process exits at once, without
    the interpreter's teardown (0.15 s with rclpy loaded: see
    :func:`winder.ros.spin.leave`). ``winder run`` says so once its cell is down."""
    ros_done.append(True)
