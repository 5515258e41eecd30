"""A winder command or node stops on SIGINT whatever its parent left it:
SIGINT ignored (a script's ``winder ... &``: POSIX has a background job
ignore it) or blocked (started from a thread that blocks it). Before, such a
process ran on until killed (make flakes, started with ``&``: ``winder ctl
state --watch`` and ``winder play --foxglove``, 3 rounds of 3). Under
``nohup`` (SIGHUP ignored) SIGHUP stays ignored."""

from __future__ import annotations

import signal
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest
from conftest import Procs
from support import wait
from support.paths import BIN

from winder.procs import die_with_parent, in_mask, kill_telling_where, signal_state

#: the processes tried: a command (stops "interrupted", 130) and a node (closes, 0)
PROCESSES = pytest.mark.parametrize(
    ("argv", "code"),
    [(["winder", "ctl", "state", "--watch", "--timeout", "60"], 130), (["sim_node"], 0)],
    ids=["winder ctl state --watch", "sim_node"],
)


def starting_with(change: Callable[[], None]) -> Callable[[], None]:
    """A ``preexec_fn``: the child dies with this process, and ``change``
    (in the child, before exec) leaves its signals as such a parent would."""
    dies = die_with_parent()  # made here: it notes this process as the parent

    def preexec() -> None:
        dies()
        change()

    return preexec


def ignore_and_block_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})


def ignore_sighup() -> None:  # as nohup does
    signal.signal(signal.SIGHUP, signal.SIG_IGN)


def started(
    procs: Procs, tmp_path: Path, argv: list[str], change: Callable[[], None]
) -> subprocess.Popen[str]:
    """``argv`` started with its signals as ``change`` leaves them, once
    winder's handlers are in (SIGTERM's: Python has none of its own)."""
    p = subprocess.Popen(
        [str(BIN / argv[0]), *argv[1:]],
        env=procs.env,
        cwd=tmp_path,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=starting_with(change),
    )
    try:
        wait.until(
            lambda: in_mask(p.pid, "SigCgt", signal.SIGTERM) or p.poll() is not None,
            60,
            "its signal handlers",
        )
        assert p.poll() is None
    except BaseException:
        p.kill()
        p.wait()
        raise
    return p


def stops_on_sigint(p: subprocess.Popen[str], code: int) -> None:
    p.send_signal(signal.SIGINT)
    try:
        _, err = p.communicate(timeout=30)
    except subprocess.TimeoutExpired:
        state = signal_state(p.pid)
        kill_telling_where(p)
        _, err = p.communicate()
        pytest.fail(f"no stop 30 s after SIGINT ({state}); its stacks:\n{err}")
    assert p.returncode == code, err
    assert "Traceback" not in err, err


@pytest.mark.ros
@PROCESSES
def test_sigint_stops_a_process_started_with_it_ignored_and_blocked(
    procs: Procs, tmp_path: Path, argv: list[str], code: int
) -> None:
    p = started(procs, tmp_path, argv, ignore_and_block_sigint)
    assert in_mask(p.pid, "SigCgt", signal.SIGINT)  # taken (before: it stayed ignored, and blocked)
    stops_on_sigint(p, code)


@pytest.mark.ros
@PROCESSES
def test_under_nohup_sighup_stays_ignored(procs: Procs, tmp_path: Path, argv: list[str], code: int) -> None:
    """`nohup winder run ... &` is how a long run outlives an ssh session: a
    winder command or node started with SIGHUP ignored leaves it ignored
    (it takes SIGINT), and stops on SIGINT."""
    p = started(procs, tmp_path, argv, ignore_sighup)
    assert in_mask(p.pid, "SigIgn", signal.SIGHUP) and not in_mask(p.pid, "SigCgt", signal.SIGHUP)
    stops_on_sigint(p, code)
