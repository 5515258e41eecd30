"""An internal error of a ``winder`` command: one line for the user, the traceback in a file.

An exception outside the error family's kinds (:mod:`winder.errors`) is a bug,
not the user's mistake: the command prints one line naming the exception and
the file its traceback went to, and ends with
:data:`winder.cli.exits.EXIT_INTERNAL`. The file is
``$XDG_STATE_HOME/winder/crash/<command>-<time>-<pid>.txt`` (by default
``~/.local/state/winder/crash/``; where that cannot be written, the system's
temporary directory), with the command line, the versions and the traceback.
"""

from __future__ import annotations

import os
import platform
import sys
import tempfile
import time
import traceback
from pathlib import Path

__all__ = ["crash_dir", "internal_error_line", "write_crash"]


def crash_dir() -> Path:
    """Where tracebacks of internal errors go: ``$XDG_STATE_HOME/winder/crash``
    (``~/.local/state/winder/crash`` when it is not set or not absolute)."""
    state = os.environ.get("XDG_STATE_HOME", "")
    base = Path(state) if os.path.isabs(state) else Path.home() / ".local" / "state"
    return base / "winder" / "crash"


def _one_line(text: str) -> str:
    lines = [s.strip() for s in text.splitlines() if s.strip()]
    return lines[0] if lines else ""


def write_crash(command: str, exc: BaseException, argv: list[str] | None = None) -> Path:
    """The traceback of ``exc`` (with the command line and the versions) in a
    new file; its path. OSError if neither place can be written."""
    from winder import __version__ as winder_version

    text = "".join(
        [
            f"winder {command}: internal error\n",
            f"command line: {' '.join(argv if argv is not None else sys.argv)}\n",
            f"winder {winder_version}, Python {platform.python_version()}, {platform.platform()}\n",
            f"time: {time.strftime('%Y-%m-%d %H:%M:%S %z')}\n\n",
            *traceback.format_exception(type(exc), exc, exc.__traceback__),
        ]
    )
    name = f"{command or 'winder'}-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
    fallback = Path(tempfile.gettempdir()) / f"winder-crash-{os.getuid()}"
    error: OSError | None = None
    for directory in (crash_dir(), fallback):
        try:
            directory.mkdir(parents=True, exist_ok=True, mode=0o700)
            path = directory / name
            with open(path, "x", encoding="utf-8") as f:
                f.write(text)
            return path
        except OSError as exc_write:
            error = exc_write
    assert error is not None
    raise error


def internal_error_line(command: str, exc: BaseException, argv: list[str] | None = None) -> str:
    """The one line ``winder <command>`` prints for an internal error, the
    traceback written to a file (:func:`write_crash`) first."""
    message = _one_line(str(exc))
    what = f"{type(exc).__name__}: {message}" if message else type(exc).__name__
    try:
        where = f"the traceback is in {write_crash(command, exc, argv)}"
    except OSError as why:
        where = f"its traceback could not be saved: {why.strerror or why}"
    return f"winder {command}: internal error: {what} (a bug; {where})"
