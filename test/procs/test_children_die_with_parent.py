"""winder.procs, the one process harness (winder run's nodes, the tests'
processes, the session's bags, the benchmarks): children die with their
parent however it dies, and a stop is SIGINT, then kill after the grace.

The oracle is the kernel: /proc says whether a process still runs."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from support import wait

from winder.procs import Children, stop

#: a parent that starts two children through the harness, prints their pids and waits
PARENT = textwrap.dedent(
    """
    import sys, time
    from pathlib import Path
    from winder.procs import Children

    children = Children(Path(sys.argv[1]))
    sleeper = [sys.executable, "-c", "import time; time.sleep(120)"]
    # one that ignores SIGINT: the parent-death signal must still end it
    ignore = "import signal, time; signal.signal(signal.SIGINT, signal.SIG_IGN); time.sleep(120)"
    stubborn = [sys.executable, "-c", ignore]
    a = children.start(sleeper, "sleeper")
    b = Children(Path(sys.argv[1]), death_signal=15).start(stubborn, "stubborn")
    print(a.pid, b.pid, flush=True)
    time.sleep(120)  # a parent that lives on until the test kills it: not a wait
    """
)


def alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie waiting for its reaper does not)."""
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state not in ("Z", "X")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="PR_SET_PDEATHSIG is Linux's")
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_a_killed_parent_leaves_no_child_running(tmp_path: Path, sig: int) -> None:
    parent = subprocess.Popen(
        [sys.executable, "-c", PARENT, str(tmp_path)], stdout=subprocess.PIPE, text=True
    )
    try:
        assert parent.stdout is not None
        pids = [int(v) for v in parent.stdout.readline().split()]
        assert len(pids) == 2 and all(alive(p) for p in pids)
        parent.send_signal(sig)
        parent.wait(timeout=10)
        wait.until(
            lambda: not [p for p in pids if alive(p)],
            10,
            "the end of the children with their parent",
            heard=lambda: [p for p in pids if alive(p)],
        )
    finally:
        parent.kill()
        parent.wait()
        for p in pids if "pids" in locals() else []:
            if alive(p):
                os.kill(p, signal.SIGKILL)


def test_stop_is_sigint_then_kill_after_the_grace(tmp_path: Path) -> None:
    children = Children(tmp_path)
    polite = children.start([sys.executable, "-c", "import time; time.sleep(60)"], "polite")
    stubborn = children.start(
        [
            sys.executable,
            "-c",
            "import signal, sys, time; from winder.procs import stacks_on_signal; stacks_on_signal();"
            " signal.signal(signal.SIGINT, signal.SIG_IGN);"
            " print('ignoring SIGINT', flush=True); time.sleep(60)",
        ],
        "stubborn",
    )
    # it ignores SIGINT from here on
    wait.log_has(
        tmp_path / "stubborn.log", "ignoring SIGINT", 30, "the stubborn child's start", running=stubborn
    )
    t0 = time.monotonic()
    assert children.stop_all(signal.SIGINT, grace=1.0) == ["stubborn"]
    assert time.monotonic() - t0 < 5
    assert polite.returncode != 0 and stubborn.returncode == -signal.SIGKILL
    log = (tmp_path / "stubborn.log").read_text()
    # a winder process asked for its stacks before the kill: its log says where it hung
    assert "ignoring SIGINT" in log and "most recent call first" in log, log
    assert children.running() == []


def test_one_stop_says_whether_the_child_stopped_by_itself(tmp_path: Path) -> None:
    p = Children(tmp_path).start([sys.executable, "-c", "import time; time.sleep(60)"], "sleeper")
    code, by_itself = stop(p, signal.SIGTERM, grace=10.0)
    assert (code, by_itself) == (-signal.SIGTERM, True)


def test_a_child_whose_parent_is_gone_before_it_is_set_up_ends_at_once(tmp_path: Path) -> None:
    """The parent dies between the fork and the child's prctl (here: the
    preexec made for another parent, so the child sees another parent id):
    the child signals itself. The parent had a Python SIGINT handler at the
    fork (winder run has one), which the child still had until its exec:
    the signal went to it and was lost at the exec, and the child lived on
    (a node of a SIGKILLed winder run, spinning an hour later). Now the
    child gives the signal its default action first: it ends, never execs."""
    script = textwrap.dedent(
        """
        import signal, subprocess, sys
        from winder.procs import die_with_parent
        signal.signal(signal.SIGINT, lambda *_: None)  # a Python handler, as winder run has
        pre = die_with_parent()
        import os
        if os.fork() == 0:  # a child process that starts the grandchild with its parent's preexec
            p = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"], preexec_fn=pre)
            try:
                code = p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
                code = "alive"
            print(code, flush=True)
            os._exit(0)
        os.wait()
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == str(-signal.SIGINT), out.stdout + out.stderr


def test_a_child_knows_whether_its_starter_is_gone() -> None:
    """winder.procs.parent_gone in a child started by popen: False while the
    starter lives; True when the pid it was given is not its parent (as after
    the starter died and the child was handed to init: a death signal lost
    while Python started must not leave a node spinning on)."""
    import subprocess as sp
    import sys as _sys

    from winder.procs import PARENT_ENV, popen

    code = "from winder.procs import parent_gone; print(parent_gone())"
    p = popen([_sys.executable, "-c", code], stdout=sp.PIPE, text=True)
    assert p.communicate(timeout=60)[0].strip() == "False"
    # a starter that is not its parent but lives (a grandchild through a shell): not gone
    env = {**__import__("os").environ, PARENT_ENV: "1"}
    out = sp.run([_sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "False"
    # a starter that is gone: a pid that was and is no more
    dead = sp.Popen(["true"])
    dead.wait()
    env = {**__import__("os").environ, PARENT_ENV: str(dead.pid)}
    out = sp.run([_sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "True"
