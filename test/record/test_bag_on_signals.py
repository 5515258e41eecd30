"""A bag is always readable or recoverable, whatever signal reaches the cell
at whatever moment of a run.

Real cells (``winder run``, the three nodes) get SIGINT or SIGHUP on their
process group (a Ctrl-C, a closed terminal), or SIGTERM or SIGKILL on the step
consumer, before the run's bag opens, the moment it appears, mid-run, and
around its close. Afterwards every bag directory of the run has its
metadata.yaml and reads with rosbags and the repo's reader, the same
messages, a SIGKILLed one too (as it is: left unclosed, without an index),
and through ``winder bag recover``. A directory that is not a bag is never
left behind (at most a hidden staging directory of a SIGKILLed open, which
the next run removes).
"""

from __future__ import annotations

import contextlib
import os
import random
import signal
import subprocess
import time
from pathlib import Path

import pytest
from conftest import BIN, Procs, next_domain, release_domain, rosbags_read
from mcap.reader import make_reader
from support import wait
from support.bags import mcap_size
from support.cli import run_cli

from winder.procs import popen
from winder.record.bag import bags_in
from winder.record.reader import BagError, read_raw, read_run

pytestmark = pytest.mark.ros

#: a job of 2048 steps, 1.4 s of simulated time, paced in real time: the bag is open about 1.6 s
JOB = ["--job-id", "sig", "--turns-per-layer", "2", "--layers", "1", "--poles", "1", "--real-time"]
#: runs per (phase, signal); WINDER_SIGNAL_REPEATS raises it to hunt a race
REPEATS = int(os.environ.get("WINDER_SIGNAL_REPEATS", "2"))
#: (signal, whom): the cell's process group as a terminal signals it, or the consumer alone
SIGNALS = [
    (signal.SIGINT, "group"),
    (signal.SIGHUP, "group"),
    (signal.SIGTERM, "consumer"),
    (signal.SIGKILL, "consumer"),
]
PHASES = ["before", "open", "mid", "close"]


def children(pid: int) -> dict[int, str]:
    """The child processes of ``pid``: pid -> command line."""
    out = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                out[int(entry)] = Path(f"/proc/{entry}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except (OSError, ValueError, IndexError):
            continue
    return out


class Cell:
    """``winder run`` in a session of its own (its process group is the cell)."""

    def __init__(self, tmp: Path, domain: int, bag_dir: Path) -> None:
        env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
            "TMPDIR": str(tmp),
        }
        self.log = tmp / "winder-run.log"
        self.p = popen(
            [str(BIN / "winder"), "run", "--bag-dir", str(bag_dir), *JOB],
            env=env,
            stdout=self.log.open("wb"),
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
        )
        self.t0 = time.monotonic()

    def consumer(self) -> int | None:
        for pid, cmd in children(self.p.pid).items():
            if "sim_node" in cmd:
                return pid
        return None

    def signal(self, sig: int, whom: str) -> None:
        if whom == "group":
            os.killpg(self.p.pid, sig)
            return
        pid = self.consumer()
        assert pid is not None, "the sim node is not running"
        os.kill(pid, sig)

    def ended(self) -> bool:
        """Whether winder run and every node of the cell have ended (winder run reaped)."""
        try:
            os.killpg(self.p.pid, 0)
        except ProcessLookupError:
            self.p.wait()
            return True
        self.p.poll()  # reaped once it ends: a zombie leader keeps its group
        return False

    def wait(self, timeout: float = 40.0) -> None:
        """Until winder run and every node of the cell have ended (killed after ``timeout``)."""
        try:
            wait.until(self.ended, timeout, "the end of the cell", heard=lambda: self.log.read_text()[-1500:])
        except wait.WaitTimeoutError:
            os.killpg(self.p.pid, signal.SIGKILL)
            self.p.wait()
            raise


def entries(bag_dir: Path) -> list[str]:
    try:
        return os.listdir(bag_dir)
    except FileNotFoundError:
        return []


def signal_at(cell: Cell, bag_dir: Path, phase: str, sig: int, whom: str, rng: random.Random) -> None:
    """Send ``sig`` at ``phase`` of the run (see the module)."""
    log = lambda: cell.log.read_text()[-1500:]  # noqa: E731 - what the cell said, if a wait fails
    if phase == "before":  # somewhere in the start: nodes starting, handshake, job description
        wait.until(lambda: cell.consumer() is not None, 20, "the sim node's process", heard=log, poll=0.005)
        time.sleep(rng.uniform(0.0, 2.5))  # the signal's moment, drawn at random: the subject, not a wait
    elif phase == "open":  # the moment anything appears in the bag directory: no sleep between looks
        wait.until(lambda: entries(bag_dir), 30, "an entry in the bag directory", heard=log, poll=0)
    elif phase == "mid":  # the run's first chunks are in the file
        wait.until(lambda: mcap_size(bag_dir) > 30_000, 30, "30 kB in the bag's file", heard=log, poll=0.001)
    else:  # around the end of the steps, when the final report is written and the bag closes
        wait.until(lambda: entries(bag_dir), 30, "an entry in the bag directory", heard=log, poll=0.001)
        time.sleep(rng.uniform(1.3, 2.0))  # the signal's moment, drawn at random: the subject, not a wait
    if cell.p.poll() is not None and whom == "group":
        return  # the run ended before the moment came: nothing to signal
    with contextlib.suppress(AssertionError, ProcessLookupError):  # the consumer had already ended
        cell.signal(sig, whom)


def check_bags(bag_dir: Path, killed: bool, tmp: Path) -> str:
    """Every bag of ``bag_dir`` readable (or recoverable, if the consumer was
    SIGKILLed); returns what was found: "none", "closed" or "recovered"."""
    found = "none"
    for entry in sorted(entries(bag_dir)):
        if entry.startswith("."):
            assert killed, f"{bag_dir / entry}: a staging directory left by a run that was not SIGKILLed"
    for path in bags_in(bag_dir):  # (the part index beside them is no bag)
        entry = path.name
        assert (path / "metadata.yaml").is_file(), f"{path}: no metadata.yaml ({os.listdir(path)})"
        try:
            raw = read_raw(path)
        except BagError as exc:
            raise AssertionError(f"{path}: not readable: {exc}") from None
        if raw.closed and not raw.recovered:
            assert not raw.damaged, raw.damaged
            run = read_run(path)
            assert run.plan.run_id and run.report, path
            rosbags_read(path)  # the reference reader opens it too
            found = "closed"
            continue
        assert killed, f"{path}: cut short ({raw.notes}), but the consumer was not SIGKILLed"
        # the reference reader opens it as it is, and reads the same messages
        ros = rosbags_read(path)
        assert {t: len(m) for t, m in ros.items() if m} == {t: n for t, n in raw.topics().items() if n}
        out = tmp / f"{entry}_recovered"
        r = run_cli("bag", "recover", str(path), "--output", str(out))
        assert r.returncode == 0, r.stdout + r.stderr
        assert "incomplete: the file was cut short" in r.stdout, r.stdout
        assert rosbags_read(out)["/winder/job"], out
        found = "recovered"
    return found


@pytest.mark.parametrize("phase", PHASES)
@pytest.mark.usefixtures("hangup_taken")  # under nohup too, SIGHUP is the terminal's hangup
@pytest.mark.parametrize(("sig", "whom"), SIGNALS, ids=[f"{s.name}-{w}" for s, w in SIGNALS])
def test_a_signal_at_any_phase_leaves_a_readable_or_recoverable_bag(
    tmp_path: Path, phase: str, sig: signal.Signals, whom: str
) -> None:
    rng = random.Random(f"{phase}-{sig}-{whom}")
    domain = next_domain()
    try:
        seen = []
        for i in range(REPEATS):
            tmp = tmp_path / f"run{i}"
            tmp.mkdir()
            bag_dir = tmp / "bags"
            cell = Cell(tmp, domain, bag_dir)
            try:
                signal_at(cell, bag_dir, phase, sig, whom, rng)
                cell.wait()
            finally:
                if cell.p.poll() is None:
                    os.killpg(cell.p.pid, signal.SIGKILL)
                    cell.p.wait()
            seen.append(check_bags(bag_dir, sig == signal.SIGKILL, tmp))
            assert "Traceback" not in cell.log.read_text(), cell.log.read_text()
    finally:
        release_domain(domain)
    print(f"{phase} {sig.name}->{whom}: {seen}")


def test_the_next_run_removes_a_sigkilled_open(tmp_path: Path) -> None:
    """A staging directory left by a consumer SIGKILLed while opening its bag
    is removed by the next bag opened beside it (its process is gone)."""
    from winder.record.bag import BagRecorder

    bag_dir = tmp_path / "bags"
    bag_dir.mkdir()
    stale = bag_dir / ".run1.opening-999999999"  # no such process: pids stay below 2**22
    stale.mkdir()
    (stale / "run1.mcap").write_bytes(b"\x89MCAP0\r\n")
    rec = BagRecorder(bag_dir / "run2", {"/winder/job": "std_msgs/msg/String"})
    rec.close()
    assert sorted(os.listdir(bag_dir)) == ["run2"]


#: a job that runs far longer than the test waits for: the bag is open when its writer is killed
LONG_JOB = ["--job-id", "killed", "--turns-per-layer", "20", "--layers", "10", "--poles", "4"]


def test_a_bag_left_unclosed_by_a_sigkill_is_named_with_its_mend(procs: Procs, tmp_path: Path) -> None:
    """``kill -9`` of the one-process cell (``winder_container``) the moment
    its run's bag appears: the bag is left unclosed, and every reader opens
    it as it is (rosbags, the mcap library: the run's description, in the
    bag from its open on). ``winder run`` says so in its one error line,
    naming ``winder bag recover <bag>``; so do the next start of a sim node
    recording into the same bag_dir, the next ``winder run`` there and
    ``winder analyze``; ``winder play`` and ``winder resim`` refuse it in
    one line naming the same. Once recovered, nothing names it any more."""
    from winder.record.bag import bags_in, unclosed_bags

    bag_dir = tmp_path / "bags"
    cell = procs.launch(
        [str(BIN / "winder"), "run", "--one-process", "--bag-dir", str(bag_dir), *LONG_JOB], "run"
    )
    log = lambda: procs.log(cell)  # noqa: E731 - what the cell said, if a wait fails
    visible = lambda: [b.name for b in bags_in(bag_dir)]  # noqa: E731 - the part index is none
    wait.until(visible, 60, "the run's bag directory", heard=log, poll=0, running=cell)
    [container] = [pid for pid, cmd in children(cell.pid).items() if "winder_container" in cmd]
    os.kill(container, signal.SIGKILL)
    code = cell.wait(timeout=60)
    [name] = visible()
    bag = bag_dir / name
    mend = f"`winder bag recover {bag}`"
    said = log()
    assert code != 0 and "Traceback" not in said, said
    [failed] = [line for line in said.splitlines() if line.startswith("winder run:")]
    assert "winder_container exited" in failed and mend in failed, said
    assert rosbags_read(bag)["/winder/job"]  # the reference reader opens it, with the run's description
    with next(bag.glob("*.mcap")).open("rb") as f:
        assert any(ch.topic == "/winder/job" for _, ch, _ in make_reader(f).iter_messages())
    assert unclosed_bags(bag_dir) == [bag]
    # the next start of a consumer recording there: one line, in its log
    sim = procs.start("sim_node", "-p", f"bag_dir:={bag_dir}")
    line = next(
        x for x in wait.log_has(lambda: procs.log(sim), mend, 30, running=sim).splitlines() if mend in x
    )
    assert "left unclosed" in line and str(bag_dir) in line, line
    procs.stop(sim)
    # the next `winder run` there says it before it starts its cell
    small = ["--job-id", "next", "--turns-per-layer", "2", "--layers", "1", "--poles", "1"]
    r = subprocess.run(
        [str(BIN / "winder"), "run", "--bag-dir", str(bag_dir), *small],
        env=procs.env,
        capture_output=True,
        text=True,
        timeout=240,
        stdin=subprocess.DEVNULL,
    )
    assert r.returncode == 0, r.stdout + r.stderr
    assert any(mend in x and "WARNING" in x for x in r.stdout.splitlines()), r.stdout
    # the commands that read it: analyze reads it as far as it is whole and names the mend,
    # play and resim refuse it in one line naming it
    r = run_cli("analyze", "--no-plots", str(bag))
    assert r.returncode == 0 and mend in r.stdout, r.stdout + r.stderr
    for command in ("play", "resim"):
        r = run_cli(command, str(bag))
        assert r.returncode == 2 and "Traceback" not in r.stderr, r.stdout + r.stderr
        assert len(r.stderr.strip().splitlines()) == 1 and mend in r.stderr, r.stderr
    r = run_cli("bag", "recover", str(bag))
    assert r.returncode == 0, r.stdout + r.stderr
    assert unclosed_bags(bag_dir) == []  # recovered beside it: not named again
