"""Single keys typed on the terminal, read without waiting: the keys of
``winder run`` and ``winder play``."""

from __future__ import annotations

import contextlib
import sys
from typing import Any

__all__ = ["KeyReader"]


class KeyReader:
    """Puts stdin in cbreak mode while it lasts (restored by :meth:`close`)
    and returns the keys typed since the last :meth:`read`; does nothing when
    stdin is not a terminal (a script, CI)."""

    def __init__(self) -> None:
        self.enabled = sys.stdin.isatty()
        self.saved: Any = None
        if self.enabled:
            import termios
            import tty

            self.saved = termios.tcgetattr(sys.stdin.fileno())
            tty.setcbreak(sys.stdin.fileno())

    def read(self) -> list[str]:
        import select

        keys = []
        while self.enabled and select.select([sys.stdin], [], [], 0)[0]:
            key = sys.stdin.read(1)
            if not key:  # the terminal hung up: nothing more will come
                self.enabled = False
                break
            keys.append(key.lower())
        return keys

    def close(self) -> None:
        if self.saved is not None:
            import termios

            saved, self.saved = self.saved, None
            # a terminal that hung up (SIGHUP) has nothing to restore
            with contextlib.suppress(termios.error, OSError, ValueError):
                termios.tcsetattr(sys.stdin.fileno(), termios.TCSADRAIN, saved)
