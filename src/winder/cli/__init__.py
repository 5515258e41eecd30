"""The ``winder`` command (``winder --help`` lists every subcommand: run, ctl, analyze, play, tune...)."""

from __future__ import annotations

import signal
import sys
from collections.abc import Sequence
from types import FrameType

__all__ = ["main"]


def main(argv: Sequence[str] | None = None) -> int:
    """The console script: :func:`winder.cli.commands.main`, imported here so
    that a Ctrl-C while the command's modules load ends it as one later
    does ("interrupted", status 130), not with a traceback of the import
    (the subcommands' own Ctrl-C is reported there, with their name).
    SIGTERM ends a command as Ctrl-C does, from its first moment on."""
    signal.signal(signal.SIGTERM, _terminate)
    try:
        from winder.cli.commands import main as run

        return run(argv)
    except KeyboardInterrupt:
        from winder.cli.exits import EXIT_INTERRUPTED

        print("winder: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def _terminate(signum: int, frame: FrameType | None) -> None:
    del signum, frame
    raise KeyboardInterrupt
