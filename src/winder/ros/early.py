"""A cell's container started before its runner knows the job
(``winder run --one-process``).

The container spends most of its start importing rclpy, numpy and the node
modules (0.3 s); the runner as long importing its own and checking the job.
:func:`prestart` starts the container first thing, while the command still
reads its arguments; the container loads its node classes and then waits on
its standard input for the rest of its command line. :meth:`EarlyContainer.hand`
sends it (the ``--ros-args``, and the environment the cell runs in: its
ROS domain, discovery range and DDS profile, chosen later) once the job is
checked; :meth:`EarlyContainer.cancel` ends it when the command ends
before a cell is started (bad input, Ctrl-C): killed outright, as it has
made no node, no DDS participant and no file yet.

Plain ``subprocess``, no ROS: imported before anything heavy.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
from collections.abc import Sequence
from pathlib import Path

from winder.procs import Children

__all__ = ["ARGS_ON_STDIN", "CELL_CLASSES", "CONTAINER", "EarlyContainer", "prestart", "wants_prestart"]

#: the executable that runs a cell's nodes in one process (winder.ros.container)
CONTAINER = "winder_container"
#: its option: load the classes, then read the rest of the command line from stdin
ARGS_ON_STDIN = "--args-on-stdin"
#: the node class of each part of a cell, in start order (the consumer first)
CELL_CLASSES = {
    "sim": "winder_sim.sim_node:SimNode",
    "profile": "winder_profile.profile_node:ProfileNode",
    "interp": "winder_interp.interp_node:InterpNode",
}


def find_executable(name: str) -> str:
    """The node executable next to this Python (the venv's bin/), else on PATH."""
    here = Path(sys.executable).parent / name
    if here.exists():
        return str(here)
    found = shutil.which(name)
    if found is None:
        raise FileNotFoundError(f"node executable {name!r} not found next to {sys.executable} or on PATH")
    return found


def wants_prestart(argv: Sequence[str]) -> bool:
    """``winder ARGV`` is a ``run --one-process`` that will start a cell here
    (not ``--check``, ``--help`` or ``--external``, which start none)."""
    if list(argv[:1]) != ["run"] or "--one-process" not in argv:
        return False
    return not any(a in ("-h", "--help", "--check") or a.startswith("--external") for a in argv)


class EarlyContainer:
    """A ``winder_container`` waiting for its arguments on a pipe; its
    output goes to ``log_dir/winder_container.log``."""

    def __init__(self, env: dict[str, str], log_dir: Path) -> None:
        self.env = env
        self.log_dir = log_dir
        self.handed = False
        self.children = Children(log_dir, env)
        self.proc = self.children.start(
            [find_executable(CONTAINER), ARGS_ON_STDIN, *CELL_CLASSES.values()],
            CONTAINER,
            stdin=subprocess.PIPE,
        )

    def hand(self, env: dict[str, str], ros_args: list[str]) -> None:
        """Send the container its ``--ros-args`` and whatever of ``env``
        differs from the environment it started with (``unset``: the names
        ``env`` no longer has); it starts the nodes. A container that has
        ended already (a node module that fails to import) gets nothing: the
        runner reports its exit."""
        self.handed = True
        if self.proc.poll() is not None:
            return
        changed = {k: v for k, v in env.items() if self.env.get(k) != v}
        unset = sorted(set(self.env) - set(env))
        self._send(json.dumps({"env": changed, "unset": unset, "ros_args": ros_args}).encode())

    def close(self) -> None:
        """Close the pipe: a container that has not had its arguments leaves, status 0."""
        self._send(b"")

    def cancel(self) -> None:
        """No cell after all: end the container and remove its log
        directory. Before it has had its arguments it has made no node, no
        DDS participant and no file: it is killed outright (it may still be
        importing, where a SIGINT prints a traceback)."""
        self.close()
        if self.handed:
            self.children.stop_all(grace=15.0)
        elif self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()
        shutil.rmtree(self.log_dir, ignore_errors=True)

    def _send(self, data: bytes) -> None:
        pipe = self.proc.stdin
        if pipe is None or pipe.closed:
            return
        # winder's commands take SIGPIPE's default (a closed pipe ends them,
        # as any Unix filter): a container gone meanwhile must not end the runner
        main = threading.current_thread() is threading.main_thread()
        old = signal.signal(signal.SIGPIPE, signal.SIG_IGN) if main else None
        try:
            pipe.write(data)
            pipe.close()
        except OSError:  # it is gone already (BrokenPipeError): the runner sees its status
            with contextlib.suppress(OSError):
                pipe.close()
        finally:
            if old is not None:
                signal.signal(signal.SIGPIPE, old)


def prestart() -> EarlyContainer:
    """Start a cell's container now, in a log directory of its own."""
    log_dir = Path(tempfile.mkdtemp(prefix="winder-cell-"))
    return EarlyContainer({**os.environ, "PYTHONUNBUFFERED": "1"}, log_dir)
