"""CiA 402 drives over CANopen (winder.drives): the SYNC the backend sends,
its CPU, and the drive twins as fast as they go, each against an anchor
measured in the same run.

    .venv/bin/python bench/bench_drives.py [--quick] [--layers N] [--no-sync]

``--layers N``: (c) and (d) on N layers of 100 turns (1024 fork steps a
turn; default 10: 1,024,000 steps; ``--quick`` 1); ``--no-sync``: (c) and
(d) only.

Everything runs in this process on python-can's ``virtual`` bus (a bus per
role on one channel, as in ``cia402_node``'s twin cell): three drive twins
(:class:`winder.drives.SimulatedDrive`, one canopen network), the backend
(:class:`winder.drives.Cia402Backend`, its own network), and a listener. No
ROS: the driver node's paced clock is played by a thread that does what
``winder.ros.driver`` does every 10 ms (``CLOCK_PERIOD_NS``): the rows due by
now to ``backend.write(t, rows)``, then ``backend.read(t)``; the backend
sends the SYNCs due meanwhile, each paced to its period.

(a) **SYNC jitter** at 4 ms and 2 ms: the intervals between SYNC frames as a
    python-can listener sees them (the virtual bus stamps each frame when it
    is sent), p50, p99 and max, during a paced run of the job; anchor:
    python-can's own ``bus.send_periodic`` of the same SYNC frame at the same
    period, on a channel of its own, for as long.
(b) **CPU per axis** at 4 ms (and 2 ms): the backend's two threads (the one
    that calls write/read, and its network's receive thread) in process time
    over wall time, divided by 3 axes; beside it the whole process (the twins
    and the listener too). Anchor: python-can's ``send_periodic`` of the four
    frames the backend sends a cycle (SYNC, three RPDOs) at the same period.
(c) **The twins as fast as possible** (``real_time`` false): a job's steps
    through the backend and three twins, steps/s; anchor: the sim node's
    motor model on the same rows (a ``StepperAxis.linear_tracker`` per axis,
    the paper's motor, as ``sim_node``'s engine runs it), sampled on the same
    SYNC grid, in chunks of 4096 rows.
(d) **Twins vs sim, positions**: both runs of (c): every step executed, the
    final positions, and the largest difference of the positions sampled at
    each SYNC, against the sim on the exact step times (what the CSP grid
    costs: a step waits for its SYNC) and against the sim fed the same
    staircase the twins got (the steps moved to their SYNC: the twin's
    motor against the sim's).
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can
import canopen
import numpy as np
import numpy.typing as npt
from _common import table

from winder.axis import StepperAxis
from winder.contract.params import PROFILE_SPECS
from winder.drives import Cia402Backend, SimulatedDrive
from winder.motion.axes import AXIS_TABLE
from winder.motion.interp import interpolate
from winder.motion.job import Job
from winder.motion.timing import plan_timing

#: the driver node's paced clock (winder.ros.driver.CLOCK_PERIOD_NS)
TICK_NS = 10_000_000
#: counts a step on every axis (the drives file's counts_per_unit = COUNTS / joint step)
COUNTS = 100
JOB = Job()
JOINT_STEP = (JOB.feed_step, 2 * math.pi / JOB.fork_steps_per_rev, 2 * math.pi / JOB.pole_steps_per_rev)
#: rows handed to the backend at once in (c), and the sim's chunk
CHUNK = 4096
_channels = iter(range(10**6))


@dataclass
class Start:
    """What Cia402Backend.begin reads of a run (winder.ros.driver.RunStart, without ROS)."""

    settings: dict[str, Any]
    axes: tuple[Any, ...] = tuple(AXIS_TABLE)
    joint_step: tuple[float, ...] = JOINT_STEP
    start: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(3, np.int64))


def job_rows(turns: int, layers: int) -> npt.NDArray[np.int64]:
    """Rows [t_ns, segment, feed, fork, pole] of a job of one pole, timed by the default ramp."""
    job = Job(turns_per_layer=turns, layers=layers, poles=1)
    values = {k: s.default for k, s in PROFILE_SPECS.items()}
    segs = list(job.segments())
    paths = [interpolate(s.start, s.delta) for s in segs]
    timings, _ = plan_timing(values, [p.shape[0] for p in paths])
    out = []
    for seg, path, timing in zip(segs, paths, timings, strict=True):
        rows = np.empty((path.shape[0], 5), np.int64)
        rows[:, 0] = timing.times_ns(np.arange(1, path.shape[0] + 1))
        rows[:, 1] = seg.index
        rows[:, 2:] = path
        out.append(rows)
    return np.vstack(out)


def drives_file(channel: str, period: float) -> Path:
    axes = ""
    for i, (axis, step) in enumerate(zip(("feed", "fork", "pole"), JOINT_STEP, strict=True)):
        axes += (
            f"  {axis}:\n    node_id: {i + 1}\n    eds: twin\n    counts_per_unit: {COUNTS / step!r}\n"
            "    mode: 8\n    following_error: {window: 4294967295, time: 0}\n"
            "    heartbeat: {producer: 100, timeout: 1000}\n"
        )
    path = Path(tempfile.mkdtemp()) / "drives.yaml"
    path.write_text(
        f"bus: {{interface: virtual, channel: {channel}}}\nsync_period: {period}\nsdo_timeout: 1.0\n"
        f"axes:\n{axes}"
    )
    return path


def thread_cpu(native_id: int) -> float:
    """A thread's user + system time (s), from /proc."""
    fields = Path(f"/proc/self/task/{native_id}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def receive_thread(network: canopen.Network) -> threading.Thread:
    """The thread a canopen network's python-can notifier reads the bus in."""
    assert network.notifier is not None
    [reader] = [r for r in network.notifier._readers if isinstance(r, threading.Thread)]
    return reader


class SyncTimes(can.Listener):
    """The send time of every SYNC (0x080) on the bus."""

    def __init__(self) -> None:
        self.times: list[float] = []

    def on_message_received(self, msg: can.Message) -> None:
        if msg.arbitration_id == 0x80:
            self.times.append(msg.timestamp)


class Rig:
    """Three twins, a backend and a listener on one virtual channel."""

    def __init__(self, period: float) -> None:
        self.channel = f"bench-drives-{os.getpid()}-{next(_channels)}"
        self.twin_net = canopen.Network()
        self.twin_net.NOTIFIER_CYCLE = 0.05
        self.twin_net.connect(interface="virtual", channel=self.channel)
        self.twins = [SimulatedDrive(self.twin_net, n) for n in (1, 2, 3)]
        self.backend = Cia402Backend(drives_file(self.channel, period))
        self.listen_bus = can.Bus(interface="virtual", channel=self.channel)
        self.syncs = SyncTimes()
        self.notifier = can.Notifier(self.listen_bus, [self.syncs], timeout=0.05)

    def close(self) -> None:
        self.notifier.stop()
        self.listen_bus.shutdown()
        self.backend.close()
        for twin in self.twins:
            twin.stop()
        self.twin_net.disconnect()


def intervals_ms(times: list[float]) -> npt.NDArray[np.float64]:
    return np.diff(np.asarray(times)) * 1e3


def stats(iv: npt.NDArray[np.float64]) -> list[str]:
    return [f"{np.percentile(iv, 50):.3f}", f"{np.percentile(iv, 99):.3f}", f"{iv.max():.3f}", str(iv.size)]


def paced_run(period: float, seconds: float, rows: npt.NDArray[np.int64]) -> dict[str, Any]:
    """The backend paced by a thread playing the driver's 10 ms clock, for ``seconds``."""
    rig = Rig(period)
    try:
        rig.backend.begin(Start({"real_time": True}))
        first_sync = len(rig.syncs.times)
        recv = receive_thread(rig.backend.network)
        done = threading.Event()
        out: dict[str, Any] = {}

        def clock() -> None:
            handed = 0
            start = time.monotonic_ns()
            next_tick = start
            cpu0, recv0, proc0 = time.thread_time(), thread_cpu(recv.native_id), time.process_time()
            while True:
                next_tick += TICK_NS
                pause = (next_tick - time.monotonic_ns()) / 1e9
                if pause > 0:
                    time.sleep(pause)
                t = time.monotonic_ns() - start
                if t > seconds * 1e9:
                    break
                n = int(np.searchsorted(rows[:, 0], t, side="right"))
                if n > handed:
                    rig.backend.write(t, rows[handed:n])
                    handed = n
                rig.backend.read(t)
            wall = (time.monotonic_ns() - start) / 1e9
            out["backend_cpu"] = (time.thread_time() - cpu0 + thread_cpu(recv.native_id) - recv0) / wall
            out["process_cpu"] = (time.process_time() - proc0) / wall
            out["fault"] = rig.backend.fault()
            done.set()

        thread = threading.Thread(target=clock, name="driver-clock")
        thread.start()
        thread.join()
        rig.backend.end()
        out["intervals"] = intervals_ms(rig.syncs.times[first_sync:])
        return out
    finally:
        rig.close()


def periodic_anchor(period: float, seconds: float, frames: int) -> dict[str, Any]:
    """python-can's send_periodic of the SYNC (and ``frames - 1`` RPDO-sized frames) for ``seconds``."""
    channel = f"bench-periodic-{os.getpid()}-{next(_channels)}"
    bus = can.Bus(interface="virtual", channel=channel)
    listen = can.Bus(interface="virtual", channel=channel)
    syncs = SyncTimes()
    notifier = can.Notifier(listen, [syncs], timeout=0.05)
    try:
        msgs = [can.Message(arbitration_id=0x80, data=b"", is_extended_id=False)]
        msgs += [
            can.Message(arbitration_id=0x200 + n, data=bytes(6), is_extended_id=False) for n in (1, 2, 3)
        ]
        before = {t.ident for t in threading.enumerate()}
        proc0, t0 = time.process_time(), time.monotonic()
        tasks = [bus.send_periodic(m, period) for m in msgs[:frames]]
        senders = [t for t in threading.enumerate() if t.ident not in before]
        cpu0 = {t.native_id: thread_cpu(t.native_id) for t in senders if t.native_id}
        time.sleep(seconds)  # the anchor's subject: python-can's own timing for this long
        cpu = sum(thread_cpu(i) - c for i, c in cpu0.items())
        wall = time.monotonic() - t0
        proc = time.process_time() - proc0
        for task in tasks:
            task.stop()
        return {"intervals": intervals_ms(syncs.times), "sender_cpu": cpu / wall, "process_cpu": proc / wall}
    finally:
        notifier.stop()
        listen.shutdown()
        bus.shutdown()


def twins_fast(rows: npt.NDArray[np.int64], period: float) -> dict[str, Any]:
    """(c) and the twins' side of (d): every row through the backend as fast as the twins answer."""
    rig = Rig(period)
    samples: list[tuple[float, float, float, float]] = []

    def on_sync(_can_id: int, _data: bytearray, _timestamp: float) -> None:
        t = rig.twins[0]
        samples.append((t.t, *(tw.position / COUNTS for tw in rig.twins)))  # motor, in steps

    try:
        rig.backend.begin(Start({"real_time": False}))
        rig.twin_net.subscribe(0x80, on_sync)  # after the twins' own handler of each SYNC
        syncs0 = rig.backend.total_syncs
        t0 = time.perf_counter()
        for i in range(0, rows.shape[0], CHUNK):
            chunk = rows[i : i + CHUNK]
            rig.backend.write(int(chunk[-1, 0]), chunk)
        settle_ns = int(rows[-1, 0]) + 500_000_000  # half a second more: the motors at rest
        rig.backend.read(settle_ns)
        elapsed = time.perf_counter() - t0
        return {
            "seconds": elapsed,
            "syncs": rig.backend.total_syncs - syncs0,
            "fault": rig.backend.fault(),
            "final": [tw.position_actual / COUNTS for tw in rig.twins],
            "samples": np.array(samples),
        }
    finally:
        rig.close()


def sim_engine(
    rows: npt.NDArray[np.int64], grid_ns: npt.NDArray[np.int64], snap_ns: int = 0
) -> dict[str, Any]:
    """The sim node's motor model on the same rows in chunks, sampled at ``grid_ns``;
    ``snap_ns``: each step moved to the SYNC it goes out at (the first multiple of it at or
    after the step's time), where a twin takes it: just after that SYNC's sample."""
    trackers = [StepperAxis.paper().linear_tracker() for _ in range(3)]
    times = rows[:, 0]
    if snap_ns:
        times = -(-times // snap_ns) * snap_ns + 1  # 1 ns after the SYNC: after its sample
    delta = np.diff(np.vstack([np.zeros((1, 3), np.int64), rows[:, 2:]]), axis=0).astype(float)
    out = np.zeros((grid_ns.size, 3))
    n = rows.shape[0]
    t0 = time.perf_counter()
    g = 0
    for i in range(0, n, CHUNK):
        sl = slice(i, min(i + CHUNK, n))
        g1 = grid_ns.size if sl.stop == n else int(np.searchsorted(grid_ns, times[sl.stop - 1], side="right"))
        ts = grid_ns[g:g1] / 1e9
        for a, tracker in enumerate(trackers):
            moved = delta[sl, a] != 0
            theta, _ = tracker.advance(times[sl][moved] / 1e9, delta[sl, a][moved], ts)
            out[g:g1, a] = theta
        g = g1
    return {"seconds": time.perf_counter() - t0, "samples": out}


def main() -> None:
    quick = "--quick" in sys.argv
    seconds = 3.0 if quick else 10.0
    if "--smoke" in sys.argv:  # a second's check that the script runs (no figure to keep)
        seconds = 1.0
    paced_rows = job_rows(40, 1)

    # (a), (b): the paced SYNC and its CPU, against python-can's periodic send
    jitter, cpu = [], []
    for period in () if "--no-sync" in sys.argv else (0.004, 0.002):
        ms = f"{period * 1e3:g} ms"
        got = paced_run(period, seconds, paced_rows)
        sync_only = periodic_anchor(period, seconds, 1)
        four = periodic_anchor(period, seconds, 4)
        if got["fault"]:
            print(f"backend fault at {ms}: {got['fault']}")
        jitter.append([ms, "cia402 backend", *stats(got["intervals"])])
        jitter.append([ms, "python-can send_periodic", *stats(sync_only["intervals"])])
        p99 = np.percentile(got["intervals"], 99) - period * 1e3
        p99_anchor = np.percentile(sync_only["intervals"], 99) - period * 1e3
        ratio = f"{p99 / p99_anchor:.1f} x" if p99_anchor > 0 else "-"
        jitter.append([ms, "p99 - period, backend / anchor", ratio, "", "", ""])
        cpu.append(
            [
                ms,
                f"{got['backend_cpu'] / 3 * 100:.2f} %",
                f"{got['process_cpu'] * 100:.1f} %",
                f"{four['sender_cpu'] * 100:.2f} %",
                f"{got['backend_cpu'] / max(four['sender_cpu'], 1e-9):.1f} x",
            ]
        )
    if jitter:
        print(f"(a) SYNC intervals seen on the bus, ms ({seconds:g} s each, a paced run of the job)")
        print(table(["period", "sender", "p50", "p99", "max", "n"], jitter))
        print(f"\n(b) CPU of a core at each period ({seconds:g} s)")
        print(
            table(
                ["period", "backend per axis", "whole process (3 twins too)",
                 "send_periodic of 4 frames", "backend (3 axes) / that"],
                cpu,
            )
        )  # fmt: skip

    # (c), (d): the twins as fast as possible against the sim's motor model
    turns, layers = (100, 1) if quick else (100, 10)
    if "--layers" in sys.argv:
        layers = int(sys.argv[sys.argv.index("--layers") + 1])
    if "--smoke" in sys.argv:
        turns, layers = 5, 1
    rows = job_rows(turns, layers)
    period = 0.004
    twins = twins_fast(rows, period)
    samples = twins["samples"]
    # the twins' time of SYNC k of the run is the first sample's + k periods; sample k is the
    # motor at that SYNC under the targets sent up to SYNC k - 1 (taken at their SYNC)
    k = np.arange(samples.shape[0])
    grid = k * round(period * 1e9)
    exact = sim_engine(rows, grid)
    snapped = sim_engine(rows, grid, round(period * 1e9))
    n = rows.shape[0]
    print(
        f"\n(c) the job of {n:,} steps ({turns} turns x {layers} layers, {rows[-1, 0] / 1e9:.1f} s of motion)"
    )
    print(
        table(
            ["what", "s", "steps/s", "vs sim"],
            [
                ["3 twins + backend, as fast as possible", f"{twins['seconds']:.1f}",
                 f"{n / twins['seconds']:,.0f}", f"{exact['seconds'] / twins['seconds']:.3f} x"],
                ["sim's motor model (3 linear trackers)", f"{exact['seconds']:.2f}",
                 f"{n / exact['seconds']:,.0f}", "1"],
            ],
        )
    )  # fmt: skip
    print(f"SYNC cycles {twins['syncs']:,} ({twins['syncs'] / twins['seconds']:,.0f} a second)")
    if twins["fault"]:  # the twins stopped there: (d) compares up to the stop only
        print(f"twins' fault: {twins['fault']} (the twins stopped; (d) below is not a comparison)")
    final_rows = rows[-1, 2:].astype(float)
    tw = samples[:, 1:]
    print("\n(d) positions, steps (feed, fork, pole)")
    print(
        table(
            ["what", "feed", "fork", "pole"],
            [
                ["the job's last row", *(f"{v:.0f}" for v in final_rows)],
                ["twins' final position actual", *(f"{v:.2f}" for v in twins["final"])],
                ["sim's final (exact step times)", *(f"{v:.4f}" for v in exact["samples"][-1])],
                ["max |twin - sim|, exact step times",
                 *(f"{v:.3f}" for v in np.abs(tw - exact["samples"]).max(axis=0))],
                ["max |twin - sim|, steps at their SYNC",
                 *(f"{v:.2e}" for v in np.abs(tw - snapped["samples"]).max(axis=0))],
            ],
        )
    )  # fmt: skip
    print(f"sampled at {samples.shape[0]:,} SYNCs ({period * 1e3:g} ms); one step is {COUNTS} counts")


if __name__ == "__main__":
    main()
