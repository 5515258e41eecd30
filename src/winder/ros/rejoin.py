"""A node held up past the DDS lease rejoins its cell by restarting its process.

A process held (SIGSTOP, a starved host, a debugger) for longer than the
lease of winder's Fast DDS profile (:data:`winder.ros.dds.LEASE`) is dropped
by every other participant. Woken, it is discovered anew, but its built-in
discovery writers may take the others for served already: in 7 of 60
measured holds of 15 and 30 s the others never learnt its endpoints again
("no publisher of winder/job matched"), and the cell refused every start
until the node was restarted by hand (issue 53; :mod:`winder.ros.wake`
makes the shorter holds harmless). Only a new participant is certain to be
learnt whole, and rclpy makes one with a new context, that is, new nodes: so
the held process, woken, ends as at Ctrl-C (a run under way closed
incomplete, with the hold as its error, its bag closed and its part
recorded) and replaces itself with the same program (``exec``: the same pid,
so whatever supervises it sees no exit), each node given back the parameters
it had at the hold, and its lifecycle state. A restarted interp node never
autostarts: a part is wound only when asked.

The new process learns of its restart from :data:`ENV` (a JSON object: the
hold in s, the parameters file, the nodes that were active, what each node
handed over), says so, and deletes the parameters file once its nodes are
made. A consumer hands over how the run it closed ended: its status and
report never left the old process (the others had dropped it), and the new
one tells them, so that the interp node and a ``Wind`` goal learn at once
how the run ended instead of giving it up after ``stall_abort``.
"""

from __future__ import annotations

import contextlib
import json
import os
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:
    from rclpy.node import Node

__all__ = ["ENV", "Restart", "exec_again", "restart_of_this_process", "run_again_as", "save_parameters"]

#: the environment variable that tells a restarted process what it was
ENV = "WINDER_REJOINED"
#: the command line a restart runs, when it is not the process' own (:func:`run_again_as`)
_command: list[str] = []


def run_again_as(argv: Sequence[str]) -> None:
    """A restart runs ``argv`` (the executable first), not the command line
    the process was started with: the cell container, whose arguments came
    on its standard input, which a restart cannot read again."""
    _command[:] = list(argv)


class Restart:
    """What a restarted process was told by the one it replaced."""

    def __init__(
        self, held: float, params: str, active: Sequence[str], carried: Mapping[str, Any] | None = None
    ) -> None:
        self.held = held
        self.params = params
        self.active = frozenset(active)
        self.carried = dict(carried or {})

    def was_active(self, node: Node) -> bool:
        return node.get_fully_qualified_name() in self.active

    def carried_for(self, node: Node) -> Any:
        """What ``node``'s predecessor handed over (its ``handover()``), or None."""
        return self.carried.get(node.get_fully_qualified_name())


def restart_of_this_process() -> Restart | None:
    """The restart this process is (None if it was started plainly, or the
    variable is not winder's). Read once: the variable is removed, so a
    process that this one starts does not take itself for restarted."""
    text = os.environ.pop(ENV, "")
    if not text:
        return None
    try:
        got = json.loads(text)
        active = [str(n) for n in got["active"]]
        return Restart(float(got["held"]), str(got["params"]), active, dict(got.get("carried", {})))
    except (ValueError, KeyError, TypeError):
        return None


def _value(value: Any) -> Any:
    """A parameter value as YAML writes it for rcl (arrays as lists)."""
    if isinstance(value, (list, tuple)) or type(value).__name__ == "array":
        return [_value(v) for v in value]
    return value


def save_parameters(values: Mapping[str, Mapping[str, Any]]) -> Path:
    """``values`` (per node's fully qualified name, parameter -> value) as a
    ROS parameters file, in a file of its own in the temporary directory."""
    from ruamel.yaml import YAML

    document = {
        fqn: {"ros__parameters": {name: _value(v) for name, v in got.items()}} for fqn, got in values.items()
    }
    fd, name = tempfile.mkstemp(prefix="winder_rejoin_", suffix=".yaml")
    yaml = YAML(typ="safe", pure=True)
    yaml.default_flow_style = False
    with os.fdopen(fd, "w") as f:
        yaml.dump(document, f)
    return Path(name)


def exec_again(held: float, params: Path, active: Sequence[str], carried: Mapping[str, Any]) -> NoReturn:
    """Replace this process with the program it runs, its arguments and a
    last ``--ros-args --params-file`` section with ``params`` (rcl takes the
    last value given for a parameter); ``carried``: what each node (by its
    fully qualified name) hands over to its successor (JSON). Returns only by
    exiting (status 1, said) if the program cannot be run again."""
    argv = [*(_command or [sys.executable, *sys.orig_argv[1:]]), "--ros-args", "--params-file", str(params)]
    told = {"held": round(held, 3), "params": str(params), "active": list(active), "carried": dict(carried)}
    os.environ[ENV] = json.dumps(told)
    try:
        os.execv(sys.executable, argv)
    except OSError as exc:
        print(f"[winder] could not restart the node ({sys.executable}: {exc}): it ends", file=sys.stderr)
        with contextlib.suppress(OSError):
            params.unlink()
        os._exit(1)
