"""Simulated axes: stepper motor model, /clock, MCAP recording."""

from __future__ import annotations

from winder.contract.params import SIM_SPECS
from winder.ros.spin import answer_help

__all__ = ["PARAMETERS", "main"]

#: the parameters the sim node declares (its settings), and what its ``--help`` lists
PARAMETERS = SIM_SPECS


def main(args: list[str] | None = None) -> None:
    """The ``sim_node`` executable: its ``--help`` answered before the node's
    module (and rclpy) is loaded, else the node, until it is stopped."""
    if not answer_help("sim_node", __doc__ or "", PARAMETERS, args):
        from winder_sim.sim_node import main as run

        run(args)
