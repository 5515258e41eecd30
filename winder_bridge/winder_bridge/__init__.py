"""The winder cell to ros2_control hardware: position commands, servo fault watch."""

from __future__ import annotations

from winder.contract.params import BRIDGE_SPECS
from winder.ros.spin import answer_help

__all__ = ["PARAMETERS", "main"]

#: the parameters the bridge node declares (its settings), and what its ``--help`` lists
PARAMETERS = BRIDGE_SPECS


def main(args: list[str] | None = None) -> None:
    """The ``bridge_node`` executable: its ``--help`` answered before the node's
    module (and rclpy) is loaded, else the node, until it is stopped."""
    if not answer_help("bridge_node", __doc__ or "", PARAMETERS, args):
        from winder_bridge.bridge_node import main as run

        run(args)
