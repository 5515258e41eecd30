"""``winder_container``: several winder nodes in one process, as a ROS 2
component container holds several components.

    winder_container winder_sim.sim_node:SimNode winder_profile.profile_node:ProfileNode \\
        winder_interp.interp_node:InterpNode --ros-args -r __ns:=/cell1 --params-file cell1.yaml

Each node is named by ``module:Class`` (a node class whose constructor takes
no argument, as every winder node's) and made in the order given; the
``--ros-args`` after them apply to every node. A parameter for one node only
goes in a parameters file under the node's fully qualified name
(``/cell1/interp_node: ros__parameters: ...``, what ``winder run
--one-process`` writes); rcl's ``-p interp_node:layers:=3`` reaches a node
only outside any namespace. The nodes
share one DDS participant and one executor thread (:func:`winder.ros.spin.spin_all`):
they find each other at once, with no discovery between processes, which is
what a cell's start-up spends most of its time on; the price is one core
and one GIL for the three (``winder run --one-process``: the start 0.5 s
sooner, a 10⁷-step job 10-20 % slower; docs/BENCHMARKS.md). The contract is
unchanged: the nodes talk over the same topics and services, and each is told apart on the graph by its own
endpoints, not its process.

``winder_container --args-on-stdin CLASSES...`` loads the classes, then
reads the rest of its command line from standard input, one JSON object
``{"ros_args": [...], "env": {...}}`` (the environment to run in: a ROS
domain, a discovery range, a DDS profile) and end of file; empty input ends
it, status 0, having made nothing. ``winder run --one-process`` starts it
so before it has read its own arguments (:mod:`winder.ros.early`).

The classes are imported by name, as pluginlib loads components: the core
library names no node package.
"""

from __future__ import annotations

import importlib
import json
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING

from winder.errors import BadInputError
from winder.ros import rejoin
from winder.ros.early import ARGS_ON_STDIN
from winder.ros.spin import install_signal_handlers, signalled, spin_all

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ["load", "main"]

USAGE = "usage: winder_container [--args-on-stdin] MODULE:CLASS [MODULE:CLASS ...] [--ros-args ...]"


class LoadError(BadInputError):
    """A node class named on the command line that cannot be made."""


def load(spec: str) -> Callable[[], Node]:
    """The node class ``spec`` (``module:Class``) names; LoadError (one line) if none."""
    from rclpy.node import Node

    module_name, sep, class_name = spec.partition(":")
    if not sep or not module_name or not class_name:
        raise LoadError(f"node {spec!r} is invalid: must be MODULE:CLASS, e.g. winder_sim.sim_node:SimNode")
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise LoadError(f"node {spec!r}: module {module_name!r} cannot be imported ({exc})") from None
    cls = getattr(module, class_name, None)
    if not (isinstance(cls, type) and issubclass(cls, Node)):
        raise LoadError(f"node {spec!r}: {module_name} has no node class {class_name!r}")
    return cls


def rest_from_stdin() -> list[str] | None:
    """With ``--args-on-stdin``: the rest of the command line, and the
    environment to run in, from standard input (one JSON object,
    ``{"ros_args": [...], "env": {...}, "unset": [...]}``, then end of file;
    what :class:`winder.ros.early.EarlyContainer` sends). None if the input
    is empty (the runner started no cell after all). A signal does not end
    the wait (it is taken quietly, :func:`winder.ros.spin.install_signal_handlers`):
    the end of the input does, which comes with the runner's end at the latest."""
    data = sys.stdin.buffer.read()
    if not data.strip():
        return None
    try:
        told = json.loads(data)
        env, ros, unset = told["env"], told["ros_args"], told.get("unset", [])
        if not (isinstance(env, dict) and isinstance(ros, list) and isinstance(unset, list)):
            raise TypeError("env must be an object, ros_args and unset lists")
    except (ValueError, KeyError, TypeError) as exc:
        print(f"winder_container: standard input {data[:80]!r} is invalid: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    for name in unset:
        os.environ.pop(str(name), None)
    os.environ.update({str(k): str(v) for k, v in env.items()})  # read by rclpy.init, which comes after
    return [str(a) for a in ros]


def main(argv: list[str] | None = None) -> None:
    # from the first moment: a SIGINT while the node modules load (the runner
    # stopping a cell it has just handed its arguments) ends the container
    # without a traceback, having started nothing
    install_signal_handlers()
    args = sys.argv[1:] if argv is None else argv
    on_stdin = args[:1] == [ARGS_ON_STDIN]
    args = args[1:] if on_stdin else args
    cut = args.index("--ros-args") if "--ros-args" in args else len(args)
    specs, ros = args[:cut], args[cut:]
    if not specs or any(s.startswith("-") for s in specs):
        print(f"winder_container: no node to run\n{USAGE}", file=sys.stderr)
        raise SystemExit(2)
    try:
        factories = [load(s) for s in specs]
    except LoadError as exc:
        print(f"winder_container: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    if on_stdin:
        rest = rest_from_stdin()
        if rest is None or signalled():
            return
        ros = [*ros, *rest]
        # a restart after a hold (winder.ros.rejoin) runs the whole command line: stdin is read
        prefix = (
            sys.orig_argv[: len(sys.orig_argv) - len(sys.argv) + 1]
            if argv is None
            else [sys.executable, "-m", __name__]
        )
        rejoin.run_again_as([sys.executable, *prefix[1:], *specs, *ros])
    spin_all(factories, ["winder_container", *ros])


if __name__ == "__main__":
    main()
