"""Ctrl-C, SIGTERM and SIGHUP for a command whose ROS work runs in a thread
beside the main thread (``winder play``).

rclpy's own handlers shut the context down from a thread of their own the
moment a signal comes. A ROS thread still waiting on that context then
crashes the process (SIGSEGV, seen in about 1 run in 15 of a Ctrl-C to a
paused ``winder play`` on a loaded machine), and a signal between
``rclpy.init`` and the node's creation, or in the middle of importing rclpy,
ended the command with a traceback or a false "not installed". So such a
command initialises rclpy without its handlers and takes the signals here:
a SIGINT, SIGTERM or SIGHUP raises :class:`KeyboardInterrupt` in the main thread
(reported "interrupted", status 130), at once, or, inside
:meth:`Interrupts.held`, as the held section ends; once the cleanup has
begun (:meth:`Interrupts.ending`) signals are ignored, so that it (stop the
ROS thread, then destroy the node, then shut rclpy down, in that order)
runs to its end. Before that every signal raises: should code that runs
Python callbacks swallow one KeyboardInterrupt, the next Ctrl-C still ends
the command.

Plain :mod:`signal`, no ROS.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType
from typing import Any

__all__ = ["Interrupts", "deferred", "ignored"]

#: the signals that end a command as Ctrl-C does: SIGHUP too (its terminal went
#: away), which by default killed the command outright, its DDS participant
#: left on the graph for the whole lease and nothing said
SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class Interrupts:
    """SIGINT, SIGTERM and SIGHUP as :class:`KeyboardInterrupt` in the main thread,
    deferred while held, ignored once the cleanup began; :meth:`install`
    from the main thread."""

    def __init__(self) -> None:
        self.depth = 0  # nesting of held()
        self.pending = False  # a signal came while held
        self.closing = False  # the cleanup began: signals are ignored
        self.previous: dict[int, Any] = {}

    def install(self) -> Interrupts:
        for sig in SIGNALS:
            if sig == signal.SIGHUP and signal.getsignal(sig) is signal.SIG_IGN:
                continue  # nohup: the command outlives its terminal
            self.previous[sig] = signal.signal(sig, self._on_signal)
        return self

    def restore(self) -> None:
        """The handlers there were before :meth:`install`."""
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)
        self.previous.clear()

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        del signum, frame
        if self.closing:
            return
        if self.depth:
            self.pending = True
            return
        raise KeyboardInterrupt

    @contextlib.contextmanager
    def held(self) -> Iterator[None]:
        """A section a signal must not cut in two (rclpy's init and the node's
        creation, an import of rclpy): a signal that comes inside it raises
        as the section ends."""
        self.depth += 1
        try:
            yield
        finally:
            self.depth -= 1
        if not self.depth and self.pending and not self.closing:
            self.pending = False
            raise KeyboardInterrupt

    def ending(self) -> None:
        """The cleanup begins: no signal interrupts it any more."""
        self.closing = True


@contextlib.contextmanager
def deferred() -> Iterator[None]:
    """A section no signal may cut (a command's modules loading: a
    KeyboardInterrupt raised inside numpy's C-extension import, or inside a
    dataclass being made, comes out as another error with a traceback): a
    SIGINT, SIGTERM or SIGHUP that comes inside it raises as it ends. The handlers
    before it are back after it. Outside the main thread, nothing is held."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupts = Interrupts().install()
    try:
        with interrupts.held():
            yield
    finally:
        interrupts.restore()


@contextlib.contextmanager
def ignored() -> Iterator[None]:
    """A cleanup no signal may interrupt: SIGINT, SIGTERM and SIGHUP are ignored
    inside it (main thread only), the handlers before it back after it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    interrupts = Interrupts().install()
    interrupts.ending()
    try:
        yield
    finally:
        interrupts.restore()
