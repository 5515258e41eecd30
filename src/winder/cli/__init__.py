"""The ``winder`` command (``winder --help`` lists every subcommand: run, ctl, analyze, play, tune...)."""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from types import FrameType

from winder.cli.lifetime import early_containers, ros_done
from winder.interrupts import deferred, ignored
from winder.procs import hangup_ignored, stacks_on_signal, take_stop_signals

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """The console script: :func:`winder.cli.commands.main`, imported here so
    that a Ctrl-C while the command's modules load ends it as one later
    does ("interrupted", status 130), not with a traceback of the import
    (the subcommands' own Ctrl-C is reported there, with their name).
    SIGTERM and SIGHUP (a closed terminal) end a command as Ctrl-C does,
    from its first moment on. ``winder --version`` alone is answered before
    the commands' modules load (half a second); the parser's ``--version``
    prints the same line."""
    if list(sys.argv[1:] if argv is None else argv) == ["--version"]:
        from winder import __version__
        from winder.cli.exits import EXIT_OK

        print(f"winder {__version__}")
        return EXIT_OK
    stacks_on_signal()  # kill -USR1: every thread's stack on stderr (where a command hangs)
    try:  # a SIGINT from the moment it is taken on ends the command "interrupted" (a traceback before)
        take_stop_signals()  # whatever the parent left ignored or blocked (a script's `winder ... &`)
        signal.signal(signal.SIGTERM, _terminate)
        if not hangup_ignored():  # under nohup the command outlives its terminal
            signal.signal(signal.SIGHUP, _terminate)

        with deferred():  # a signal while the modules load is taken once they are loaded
            if argv is None:  # the console script: a cell's container can start while the command loads
                from winder.ros.early import prestart, wants_prestart

                if wants_prestart(sys.argv[1:]):
                    early_containers.append(prestart())
            from winder.cli.commands import main as run
        rc = run(argv)
    except KeyboardInterrupt:
        from winder.cli.exits import EXIT_INTERRUPTED

        print("winder: interrupted", file=sys.stderr)
        rc = EXIT_INTERRUPTED
    finally:
        if early_containers:  # not taken by a cell (bad input, Ctrl-C): ended, signals ignored meanwhile
            with ignored():
                while early_containers:
                    early_containers.pop().cancel()
    if ros_done and argv is None:  # the console script, not a caller's in-process call
        from winder.ros.spin import leave

        leave(rc)
    return rc


def _terminate(signum: int, frame: FrameType | None) -> None:
    del signum, frame
    raise KeyboardInterrupt
