"""The session's bags: each configuration of ``winder run`` in CONFIGS runs
once per test session (a few at a time, each on a ROS domain of its own) and
is shared by every test that asks for it through conftest's ``bag`` fixture;
and the ways tests read or write bags independently of winder's reader."""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from support import wait
from support.domains import next_domain, release_domain, take_domain
from support.paths import BIN
from winder.procs import Children, stop_all
from winder.record.bag import BagRecorder, bags_in
from winder.record.msgtypes import jazzy_store
from winder.record.raw import RawBag

SMALL = ["--turns-per-layer", "3", "--poles", "2"]
CONFIGS: dict[str, list[str]] = {
    # linear motor, S-curve, fine sampling: identification and analysis
    # (uncompressed chunks: test_cut_short_files finds each message's bytes in the file)
    "lin2k": ["--job-id", "lin2k", *SMALL, "--publish-rate", "2000", "--bag-compression", "none"],
    # nonlinear motor with non-default J and D, in a namespace
    "nlns": [
        "--job-id",
        "nlns",
        "--model",
        "nonlinear",
        "--turns-per-layer",
        "2",
        "--poles",
        "2",
        "--fork.J",
        "2e-4",
        "--feed.D",
        "0.01",
        "--pole.J",
        "5e-5",
        "--publish-rate",
        "2000",
        "--namespace",
        "/cell1",
    ],
    # the same job as lin2k with the other two ramps, default 200 Hz sampling
    "trap": ["--job-id", "trap", *SMALL, "--profile", "trapezoid"],
    "expo": ["--job-id", "expo", *SMALL, "--profile", "exponential"],
    # the trapezoid job on a rectangular core: the sim node simulates the wire too
    "wire": [
        "--job-id",
        "wire",
        *SMALL,
        "--profile",
        "trapezoid",
        "--bobbin.core",
        "rect",
        "--bobbin.core-width",
        "0.012",
        "--bobbin.core-depth",
        "0.02",
    ],
    # too fast for the pole axis: it falls out of step (pull-out speed T_m/D = 6.7 rad/s)
    "slip": [
        "--job-id",
        "slip",
        "--model",
        "nonlinear",
        "--profile",
        "trapezoid",
        "--a-max",
        "4e5",
        "--v-max",
        "12000",
        "--fork.D",
        "0.003",
        *SMALL,
        "--publish-rate",
        "2000",
    ],
    # a feed motor too weak for its load (a fifth of its current, nonlinear model): it loses steps
    "feedslip": [
        "--job-id",
        "feedslip",
        "--model",
        "nonlinear",
        "--feed.i-a",
        "0.3",
        "--turns-per-layer",
        "6",
        "--poles",
        "1",
        "--publish-rate",
        "2000",
    ],
    # one coil: the pole axis never moves
    "pole1": ["--job-id", "pole1", "--turns-per-layer", "2", "--layers", "1", "--poles", "1"],
    # aborted a third of the way (the job lasts about 6.5 s): winder analyze counts what was simulated
    "abort": ["--job-id", "abort", *SMALL, "--schedule", "abort@2"],
}


#: winder run's exit status where it is not 0 (done): 3, aborted cleanly; 6, done with lost steps
STATUS = {"abort": 3, "slip": 6, "feedslip": 6}
PARALLEL = 3
TIMEOUT = 240.0


class SessionBags:
    """Runs ``winder run`` for each configuration, at most PARALLEL at a time,
    as children that die with the test process (:class:`winder.procs.Children`),
    each on a ROS domain of its own held only while it runs: a bag is a file,
    and the tests that read it need no domain. :meth:`get` returns once every
    run it started has ended, so neither a run nor its domain outlives the
    test that asked (a worker that kept each run's domain to the session's
    end held all 10 of a 10-domain pool, and every later node test failed)."""

    def __init__(self, root: Path) -> None:
        self.root = root
        self.pending = list(CONFIGS)
        self.children = Children(root)
        #: name -> the run's process, its start (monotonic) and its domain
        self.running: dict[str, tuple[subprocess.Popen[bytes], float, int]] = {}
        self.done: dict[str, Path | str] = {}

    def _start(self, name: str, domain: int) -> None:
        env = {
            **os.environ,
            "ROS_DOMAIN_ID": str(domain),
            "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
        }
        shutil.rmtree(self.root / name, ignore_errors=True)  # a bag of a run stopped before
        p = self.children.start(
            [str(BIN / "winder"), "run", "--bag-dir", str(self.root / name), *CONFIGS[name]], name, env=env
        )
        self.running[name] = (p, time.monotonic(), domain)

    def _finish(self, name: str, p: subprocess.Popen[bytes]) -> None:
        log = self.children.log(p)
        bags = bags_in(self.root / name)
        if p.returncode != STATUS.get(name, 0) or len(bags) != 1:
            self.done[name] = f"winder run {name} failed (status {p.returncode}, bags {bags}):\n{log}"
        else:
            self.done[name] = bags[0]

    def _reap(self) -> None:
        """Each run that ended (or ran past TIMEOUT: killed) done, its domain handed back."""
        for name, (p, t0, domain) in list(self.running.items()):
            if p.poll() is None and time.monotonic() - t0 > TIMEOUT:
                p.kill()
                p.wait()
                self.done[name] = f"winder run {name} did not finish within {TIMEOUT} s"
            elif p.poll() is not None:
                self._finish(name, p)
            else:
                continue
            del self.running[name]
            release_domain(domain)

    def get(self, name: str) -> Path:
        """The bag directory of configuration ``name``, once its run ended."""
        if name not in CONFIGS:
            raise KeyError(f"no session bag {name!r}: one of {sorted(CONFIGS)}")
        if name in self.pending:
            self.pending.remove(name)
            self.pending.insert(0, name)

        def ready() -> bool:  # runs the queue on; true once `name` is done and no run goes on
            self._reap()
            while name not in self.done and self.pending and len(self.running) < PARALLEL:
                # beside a run only a domain free now; with none running, one waited for (within a bound)
                domain = take_domain() if self.running else next_domain()
                if domain is None:
                    break
                self._start(self.pending.pop(0), domain)
            return name in self.done and not self.running

        # each run ends within TIMEOUT (killed after it), a few at a time: the bound only guards this loop
        bound = TIMEOUT * (len(CONFIGS) // PARALLEL + 2)
        try:
            wait.until(
                ready, bound, f"the session's run {name}", heard=lambda: sorted(self.running), poll=0.05
            )
        finally:
            self._stop_running()  # none but after a failure
        got = self.done[name]
        if isinstance(got, str):
            raise AssertionError(got)
        return got

    def _stop_running(self) -> None:
        """Stop the runs still going (SIGINT, then kill), hand their domains
        back, and queue them again (the next :meth:`get` starts them anew)."""
        stop_all([p for p, _, _ in self.running.values()], signal.SIGINT, 20.0)
        for name, (_, _, domain) in self.running.items():
            release_domain(domain)
            self.pending.insert(0, name)
        self.running.clear()

    def close(self) -> None:
        self._stop_running()
        self.children.stop_all(signal.SIGINT, 20.0)


def finished_run(bags: Path, run_id: str, timeout: float = 60) -> Any:
    """The run ``run_id`` as read from ``bags/run_id`` (winder.record.reader.read_run),
    once its bag holds the final report: the bag is there from the run's first moment."""
    from winder.record.reader import read_run

    wait.until(
        lambda: (bags / run_id / "metadata.yaml").exists() and read_run(bags / run_id).report.get("state"),
        timeout,
        f"the final report of run {run_id} in its bag",
        heard=lambda: sorted(b.name for b in bags.iterdir()) if bags.is_dir() else "no bags",
        poll=0.2,  # each look reads the bag
    )
    return read_run(bags / run_id)


def mcap_size(bag_dir: Path) -> int:
    """The bytes of the .mcap files of the bags in ``bag_dir`` now. A bag opens
    in a hidden directory renamed once it is set up: a file listed there may be
    gone when it is looked at (FileNotFoundError in a fresh-clone CI run); it
    counts then as nothing yet, and the next look finds it renamed. The glob
    itself raised it too, listing the hidden directory as it was renamed (3 of
    4 'mid' tests of test_bag_on_signals.py in one fresh-clone CI run)."""
    total = 0
    with contextlib.suppress(FileNotFoundError):  # the glob itself, when the directory goes as it lists it
        for f in bag_dir.glob("*/*.mcap"):
            with contextlib.suppress(FileNotFoundError):
                total += f.stat().st_size
    return total


def rosbags_raw(path: Path) -> list[tuple[str, int, bytes]]:
    with AnyReader([path]) as reader:
        return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]


def joint_arrays(msgs: list[tuple[int, Any]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for _, m in msgs])
    order = [list(msgs[0][1].name).index(a) for a in ("feed", "fork", "pole")]
    pos = np.array([np.asarray(m.position)[order] for _, m in msgs])
    vel = np.array([np.asarray(m.velocity)[order] for _, m in msgs])
    return t, pos, vel


def step_rows(msgs: list[tuple[int, Any]]) -> np.ndarray:
    return np.vstack([np.asarray(m.data, dtype=np.int64).reshape(-1, 5) for _, m in msgs])


def write_bag(path: Path, messages: list[tuple[str, str, int, Any]], storage: StoragePlugin) -> None:
    store = jazzy_store()  # Jazzy's types and winder's own (winder/state's CellState)
    with Writer(path, version=9, storage_plugin=storage) as w:
        conns: dict[str, Any] = {}
        for topic, msgtype, _, _ in messages:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, msgtype, typestore=store)
        for topic, msgtype, t, msg in messages:
            w.write(conns[topic], t, store.serialize_cdr(msg, msgtype))


def rewrite(raw: RawBag, out: Path, compression: str) -> Path:
    """The messages of ``raw`` written again by the sim node's BagRecorder."""
    topics = {c.topic: c.msgtype for c in raw.connections.values()}
    rec = BagRecorder(out, topics, compression=compression)
    for cid, t, data in raw.messages:
        rec.write(raw.connections[cid].topic, t, data, exact=True)
    rec.close()
    return out


def job_doc(msg: Any) -> dict[str, Any]:
    """A recorded ``winder/job`` message (a winder_interfaces/JobDescription, or
    the std_msgs/String of older bags) as its description's
    JSON keys, for a test about something else (the typed form is checked
    against the text in test/contract/test_typed_messages.py)."""
    import json

    from winder.contract.stream import description_text

    doc: dict[str, Any] = json.loads(description_text(msg))
    return doc


def control_docs(msgs: list[tuple[int, Any]]) -> list[dict[str, Any]]:
    """Recorded ``winder/control`` messages as their events' JSON keys (a key
    not said left out), typed or the String of older bags."""
    import json

    from winder.contract.events import ControlEvent

    return [json.loads(ControlEvent.from_message(m).to_wire()) for _, m in msgs]
