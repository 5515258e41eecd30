"""Trajectory node: winding job to minimum-deviation step commands."""

from __future__ import annotations

from winder.contract.params import INTERP_SPECS
from winder.ros.spin import answer_help

__all__ = ["PARAMETERS", "main"]

#: the parameters the interp node declares (its settings), and what its ``--help`` lists
PARAMETERS = INTERP_SPECS


def main(args: list[str] | None = None) -> None:
    """The ``interp_node`` executable: its ``--help`` answered before the node's
    module (and rclpy) is loaded, else the node, until it is stopped."""
    if not answer_help("interp_node", __doc__ or "", PARAMETERS, args):
        from winder_interp.interp_node import main as run

        run(args)
