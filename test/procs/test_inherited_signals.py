"""A winder command or node stops on SIGINT whatever its parent left it:
SIGINT ignored (a script's ``winder ... &``: POSIX has a background job
ignore it) or blocked (started from a thread that blocks it). Before, such a
process ran on until killed (make flakes, started with ``&``: ``winder ctl
state --watch`` and ``winder play --foxglove``, 3 rounds of 3)."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import Procs
from support import wait
from support.paths import BIN

from winder.procs import die_with_parent


def caught(pid: int, signum: int) -> bool:
    """Whether ``pid`` has a handler of its own for ``signum`` (its SigCgt mask)."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return False
    mask = next((ln.split()[1] for ln in status.splitlines() if ln.startswith("SigCgt:")), "0")
    return bool(int(mask, 16) >> (signum - 1) & 1)


def ignoring_and_blocking_sigint() -> Callable[[], None]:
    """A ``preexec_fn``: the child dies with this process, and starts with
    SIGINT ignored and blocked, as such a parent leaves it."""
    dies = die_with_parent()  # made here: it notes this process as the parent

    def preexec() -> None:
        dies()
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})

    return preexec


@pytest.mark.ros
@pytest.mark.parametrize(
    ("argv", "code"),
    [
        (["winder", "ctl", "state", "--watch", "--timeout", "60"], 130),  # the command's "interrupted"
        (["sim_node"], 0),  # a node: it closes and exits 0
    ],
    ids=["winder ctl state --watch", "sim_node"],
)
def test_sigint_stops_a_process_started_with_it_ignored_and_blocked(
    procs: Procs, tmp_path: Path, argv: list[str], code: int
) -> None:
    p = subprocess.Popen(
        [str(BIN / argv[0]), *argv[1:]],
        env=procs.env,
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ignoring_and_blocking_sigint(),
    )
    try:
        # winder's handlers in (SIGTERM's: Python has none of its own), and SIGINT taken
        # (before: it stayed ignored, and blocked)
        wait.until(lambda: caught(p.pid, signal.SIGTERM) or p.poll() is not None, 60, "its signal handlers")
        assert caught(p.pid, signal.SIGINT)
        assert p.poll() is None
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
        assert p.returncode == code, err
        assert "Traceback" not in err, err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def ignoring_sighup() -> Callable[[], None]:
    """A ``preexec_fn``: as ``nohup`` starts a command (SIGHUP ignored)."""
    dies = die_with_parent()

    def preexec() -> None:
        dies()
        signal.signal(signal.SIGHUP, signal.SIG_IGN)

    return preexec


def ignored(pid: int, signum: int) -> bool:
    status = Path(f"/proc/{pid}/status").read_text()
    mask = next((ln.split()[1] for ln in status.splitlines() if ln.startswith("SigIgn:")), "0")
    return bool(int(mask, 16) >> (signum - 1) & 1)


@pytest.mark.ros
@pytest.mark.parametrize("argv", [["winder", "ctl", "state", "--watch", "--timeout", "60"], ["sim_node"]])
def test_under_nohup_sighup_stays_ignored(procs: Procs, tmp_path: Path, argv: list[str]) -> None:
    """`nohup winder run ... &` is how a long run outlives an ssh session: a
    winder command or node started with SIGHUP ignored leaves it ignored
    (it takes SIGINT), and stops on SIGINT."""
    p = subprocess.Popen(
        [str(BIN / argv[0]), *argv[1:]],
        env=procs.env,
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=ignoring_sighup(),
    )
    try:
        # winder's handlers in (SIGTERM's: Python has none of its own): SIGHUP left alone
        wait.until(lambda: caught(p.pid, signal.SIGTERM) or p.poll() is not None, 60, "its signal handlers")
        assert p.poll() is None
        assert ignored(p.pid, signal.SIGHUP) and not caught(p.pid, signal.SIGHUP)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=30)
        assert p.returncode in (0, 130) and "Traceback" not in err, err
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
