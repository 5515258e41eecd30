"""Profile node: S-curve, trapezoid or exponential step timing."""

from __future__ import annotations

from winder.contract.params import OPERATION_SPECS, PROFILE_SPECS
from winder.ros.spin import answer_help

__all__ = ["PARAMETERS", "main"]

#: the parameters the profile node declares (its settings), and what its ``--help`` lists
PARAMETERS = {**PROFILE_SPECS, **OPERATION_SPECS}


def main(args: list[str] | None = None) -> None:
    """The ``profile_node`` executable: its ``--help`` answered before the node's
    module (and rclpy) is loaded, else the node, until it is stopped."""
    if not answer_help("profile_node", __doc__ or "", PARAMETERS, args):
        from winder_profile.profile_node import main as run

        run(args)
