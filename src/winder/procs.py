"""Child processes that die with their parent: the one process harness of
``winder run`` (its nodes), the tests and the benchmarks.

Every child is started with Linux's parent-death signal
(``prctl(PR_SET_PDEATHSIG)``, set in the child before it executes): when the
process that started it dies, however it dies (SIGKILL included), the kernel
sends the child ``death_signal``, SIGINT by default, which a winder node
takes as Ctrl-C and so closes its bag. :meth:`Children.stop` sends SIGINT and
kills what is still running after a grace period. Each child's output goes to
its own log file.

The kernel sends the signal when the *thread* that started the child ends,
so start children from the main thread (or one that lives as long as they
should).

Plain ``subprocess`` and ``ctypes``, no ROS: it is the bottom layer.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import Any

#: ``PR_SET_PDEATHSIG`` of <linux/prctl.h>
_PR_SET_PDEATHSIG = 1


def die_with_parent(sig: int = signal.SIGINT) -> Callable[[], None]:
    """A ``preexec_fn`` for :class:`subprocess.Popen`: the child gets ``sig``
    when the process that started it dies (on Linux; elsewhere nothing), with
    its default action and unblocked, whatever this process inherited. If
    the parent died before the child set this up, the child signals itself."""
    parent = os.getpid()

    def _preexec() -> None:
        # the signal must be able to end the child however this process was started: a
        # death signal ignored (inherited from a script's `cmd &`) or blocked is lost, and a
        # node still loading when its parent was killed lived on (test_no_node_outlives_...)
        signal.signal(sig, signal.SIG_DFL)
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {sig})
        if sys.platform.startswith("linux"):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, sig)
            if os.getppid() != parent:  # the parent is already gone: the kernel will not tell
                os.kill(os.getpid(), sig)

    return _preexec


#: the environment variable a child started here finds this process' pid in
#: (:func:`parent_gone`)
PARENT_ENV = "WINDER_PARENT_PID"


def _with_parent(kwargs: dict[str, Any]) -> dict[str, Any]:
    env = kwargs.get("env")
    return {**kwargs, "env": {**(os.environ if env is None else env), PARENT_ENV: str(os.getpid())}}


def parent_gone() -> bool:
    """Whether the winder process that started this one is gone. Its death
    signal can come while Python is still starting, where it may be lost: a
    KeyboardInterrupt inside the import a ``.pth`` file runs is caught and
    printed by ``site`` as "Error processing line 1", and the node then came
    up and spun on, an orphan (a fresh-clone run). A process that finds its
    starter gone once its handlers are in ends instead."""
    parent = os.environ.get(PARENT_ENV, "")
    if not parent.isdigit() or os.getppid() == int(parent):
        return False
    # not its parent: a grandchild that inherited the variable (a shell's `node &`), whose
    # starter lives on, or the child of a starter that is gone
    try:
        os.kill(int(parent), 0)
    except ProcessLookupError:
        return True
    except OSError:  # there, but not ours to signal
        return False
    return False


def run(
    argv: Sequence[str], *, death_signal: int = signal.SIGINT, **kwargs: Any
) -> subprocess.CompletedProcess[Any]:
    """:func:`subprocess.run` for a child that dies with this process."""
    return subprocess.run(argv, preexec_fn=die_with_parent(death_signal), **_with_parent(kwargs))


def popen(argv: Sequence[str], *, death_signal: int = signal.SIGINT, **kwargs: Any) -> subprocess.Popen[Any]:
    """:class:`subprocess.Popen` for a child that dies with this process."""
    return subprocess.Popen(list(argv), preexec_fn=die_with_parent(death_signal), **_with_parent(kwargs))


def stop_all(
    procs: Iterable[subprocess.Popen[Any]], sig: int = signal.SIGINT, grace: float = 20.0
) -> list[int]:
    """Signal every running process of ``procs`` at once, wait up to ``grace``
    seconds for each, kill the rest: the pids of those that had to be killed."""
    procs = list(procs)
    for p in procs:
        if p.poll() is None:
            p.send_signal(sig)
    killed = []
    for p in procs:
        try:
            p.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            kill_telling_where(p)
            p.wait()
            killed.append(p.pid)
    return killed


def stop(p: subprocess.Popen[Any], sig: int = signal.SIGINT, grace: float = 20.0) -> tuple[int, bool]:
    """Send ``sig`` to ``p`` (if it still runs), wait ``grace`` seconds, then
    kill it (after asking for its stacks: :func:`kill_telling_where`): its
    exit status and whether it stopped by itself."""
    if p.poll() is None:
        p.send_signal(sig)
    try:
        return p.wait(timeout=grace), True
    except subprocess.TimeoutExpired:
        kill_telling_where(p)
        return p.wait(), False


#: the signals that stop a winder command or node (SIGHUP: its terminal went away)
STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def take_stop_signals() -> None:
    """Make SIGINT, SIGTERM and SIGHUP reach this process whatever it inherited
    (main thread; every winder command and node calls this first). A process
    started in the background of a script (``cmd &``: SIGINT ignored, as POSIX
    has it), under ``nohup`` (SIGHUP ignored) or by a thread that blocks them
    inherits that, and a ``kill -INT`` from whoever supervises it (a cell
    runner, ros2 launch, a test) did nothing: ``winder play --foxglove`` and
    ``winder ctl state --watch`` ran on until killed (make flakes, 3 of 3,
    started with ``&``). As a ROS node does, winder stops on them: an ignored
    one gets its default action back (SIGINT: KeyboardInterrupt), and none
    stays blocked. Handlers installed later (rclpy's, a node's) take over.
    An ignored SIGHUP stays ignored: that is ``nohup``'s whole point (a run
    that outlives its ssh session), and :func:`hangup_ignored` tells the
    callers not to take it."""
    import threading

    if threading.current_thread() is not threading.main_thread():
        return
    for sig in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(sig) is signal.SIG_IGN:
            signal.signal(sig, signal.default_int_handler if sig == signal.SIGINT else signal.SIG_DFL)
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)


def hangup_ignored() -> bool:
    """Whether SIGHUP is ignored here (started under ``nohup``): then a
    winder process leaves it so, and outlives its terminal."""
    return signal.getsignal(signal.SIGHUP) is signal.SIG_IGN


#: a winder process writes every thread's Python stack to its stderr on this
#: signal (:func:`stacks_on_signal`): ``kill -USR1 <pid>`` says where one hangs
STACKS_SIGNAL = signal.SIGUSR1


def stacks_on_signal() -> None:
    """Write every thread's stack to stderr on :data:`STACKS_SIGNAL` (every
    winder command and node calls this first). Harmless if never sent."""
    import faulthandler

    with contextlib.suppress(ValueError, OSError, AttributeError):  # no stderr, or not the main thread
        faulthandler.register(STACKS_SIGNAL, all_threads=True, chain=False)


def signal_masks(pid: int) -> dict[str, int]:
    """The signal masks of ``pid`` from /proc (``SigBlk``, ``SigIgn``,
    ``SigCgt``: has a handler, ``SigPnd``, ``ShdPnd``); {} once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return {}
    out = {}
    for line in status.splitlines():
        key, _, value = line.partition(":")
        if key in ("SigBlk", "SigIgn", "SigCgt", "SigPnd", "ShdPnd"):
            out[key] = int(value.strip(), 16)
    return out


def in_mask(pid: int, mask: str, signum: int) -> bool:
    """Whether ``signum`` is in ``pid``'s ``mask`` (:func:`signal_masks`)."""
    return bool(signal_masks(pid).get(mask, 0) >> (signum - 1) & 1)


def signal_state(pid: int) -> str:
    """The signals ``pid`` blocks, ignores and has pending (from /proc; "" where
    there is none): why a process did not stop when asked."""
    out = []
    for key, mask in signal_masks(pid).items():
        if key != "SigCgt":
            names = [signal.Signals(n).name for n in range(1, 65) if mask >> (n - 1) & 1 and n in _NAMED]
            out.append(f"{key} {', '.join(names) or '-'}")
    return "; ".join(out)


_NAMED = {int(s) for s in signal.Signals}


def kill_telling_where(p: subprocess.Popen[Any], wait: float = 1.0) -> None:
    """Kill ``p``, a process that did not stop when asked: first
    :data:`STACKS_SIGNAL`, so that its log says where it hung (and its signal
    state, on stderr of this process), then SIGKILL."""
    if p.poll() is None:
        state = signal_state(p.pid)
        if state:
            print(
                f"pid {p.pid} did not stop: {state}",
                file=sys.stderr,
                flush=True,
            )
        with contextlib.suppress(ProcessLookupError):
            p.send_signal(STACKS_SIGNAL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            p.wait(timeout=wait)
    if p.poll() is None:
        p.kill()


class Children:
    """Child processes of one owner (a cell, a test, a benchmark), each logged
    to ``log_dir/<name>.log`` (or where ``stdout`` says), each dying with this
    process; :meth:`stop_all` stops them all (``sig``, then kill after
    ``grace`` seconds)."""

    def __init__(
        self,
        log_dir: Path | None = None,
        env: dict[str, str] | None = None,
        death_signal: int = signal.SIGINT,
    ) -> None:
        self.log_dir = log_dir
        self.env = env
        self.death_signal = death_signal
        #: every child started, with its log file (None: its output went elsewhere)
        self.started: list[tuple[subprocess.Popen[Any], str, Path | None]] = []

    def start(
        self,
        argv: Sequence[str],
        name: str,
        *,
        env: dict[str, str] | None = None,
        stdout: Any = None,
        **kwargs: Any,
    ) -> subprocess.Popen[Any]:
        """Start ``argv`` as child ``name``. Its output goes to ``stdout`` when
        given (a file, ``subprocess.PIPE``, ``DEVNULL``), else to
        ``log_dir/<name>.log`` (stderr with it), else nowhere."""
        log: Path | None = None
        kwargs.setdefault("stdin", subprocess.DEVNULL)
        if stdout is None and self.log_dir is not None:
            log = self.log_dir / f"{name}.log"
            kwargs.setdefault("stderr", subprocess.STDOUT)
            with log.open("wb") as out:  # the child holds its own copy
                p = self._popen(argv, env, out, kwargs)
        else:
            p = self._popen(argv, env, subprocess.DEVNULL if stdout is None else stdout, kwargs)
        self.started.append((p, name, log))
        return p

    def _popen(
        self, argv: Sequence[str], env: dict[str, str] | None, stdout: Any, kwargs: Any
    ) -> subprocess.Popen[Any]:
        env = env if env is not None else self.env
        return popen(argv, death_signal=self.death_signal, env=env, stdout=stdout, **kwargs)

    def log(self, p: subprocess.Popen[Any]) -> str:
        """What child ``p`` wrote to its log file."""
        for q, _, path in self.started:
            if q is p and path is not None:
                return path.read_text(errors="replace")
        raise KeyError(p)

    def running(self) -> list[subprocess.Popen[Any]]:
        return [p for p, _, _ in self.started if p.poll() is None]

    def stop_all(self, sig: int = signal.SIGINT, grace: float = 20.0) -> list[str]:
        """Signal every running child at once, wait up to ``grace`` seconds
        for each, kill the rest: the names of those that had to be killed."""
        killed = stop_all([p for p, _, _ in self.started], sig, grace)
        return [name for p, name, _ in self.started if p.pid in killed]
