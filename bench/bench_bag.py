"""Bag writing MB/s of ``winder.record.bag.BagRecorder`` against the mcap library's
plain writer (``mcap.writer.Writer``, no compression, 1 MiB chunks: the same
file layout BagRecorder's rosbags writer makes) on the same serialized
messages, measured in the same run, plus where BagRecorder's time goes.

    .venv/bin/python bench/bench_bag.py [--quick]

Messages, serialized by rclpy as the sim node receives / makes them:
* step_times: Int64MultiArray chunks of 8192 x 5 int64 (328 kB each), the big ones;
* joint_states: sensor_msgs/JointState of 3 joints (position, velocity, no
  effort), 200 Hz stamps, ~150 B each: the small ones, where the cost per
  message counts.

Rows "rosbags Writer" (what BagRecorder wraps, without cdr_exact) and
"cdr_exact alone" split BagRecorder's time into its two parts.
"""

from __future__ import annotations

import array
import cProfile
import io
import pstats
import shutil
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
from _common import best_of, table
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rclpy.serialization import serialize_message
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as RosbagsWriter
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Int64MultiArray, MultiArrayDimension

from winder.record.bag import BagRecorder, cdr_exact

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
Payloads = list[tuple[int, bytes]]  # (log time ns, CDR bytes)


def step_time_chunks(count: int) -> Payloads:
    out = []
    rows = 8192
    for c in range(count):
        a = np.zeros((rows, 5), np.int64)
        a[:, 0] = (c * rows + np.arange(rows)) * 100_000
        a[:, 3] = c * rows + np.arange(1, rows + 1)
        msg = Int64MultiArray()
        msg.layout.dim = [
            MultiArrayDimension(label="steps", size=rows, stride=rows * 5),
            MultiArrayDimension(label="t_ns,segment,feed,fork,pole", size=5, stride=5),
        ]
        msg.data = array.array("q", a.tobytes())
        out.append((int(a[0, 0]), serialize_message(msg)))
    return out


def clocks(count: int) -> Payloads:
    out = []
    for k in range(count):
        t = k * 5_000_000
        msg = Clock()
        msg.clock.sec, msg.clock.nanosec = divmod(t, 1_000_000_000)
        out.append((t, serialize_message(msg)))
    return out


def joint_states(count: int) -> Payloads:
    out = []
    rng = np.random.default_rng(1)
    for k in range(count):
        t = k * 5_000_000
        msg = JointState(name=["feed", "fork", "pole"])
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t, 1_000_000_000)
        msg.header.frame_id = "rw400"
        msg.position = rng.normal(size=3).tolist()
        msg.velocity = rng.normal(size=3).tolist()
        out.append((t, serialize_message(msg)))
    return out


def best_in_dir(fn: Callable[[Path], None], repeat: int) -> float:
    """Smallest wall time of ``fn(fresh empty directory)``; making and removing
    the directory is not timed."""
    best = float("inf")
    for _ in range(repeat):
        d = Path(tempfile.mkdtemp(prefix="winder-bench-bag-"))
        try:
            t0 = time.perf_counter()
            fn(d)
            best = min(best, time.perf_counter() - t0)
        finally:
            shutil.rmtree(d, ignore_errors=True)
    return best


def once_in_dir(fn: Callable[[Path], None]) -> Callable[[], None]:
    def run() -> None:
        d = Path(tempfile.mkdtemp(prefix="winder-bench-bag-"))
        try:
            fn(d)
        finally:
            shutil.rmtree(d, ignore_errors=True)

    return run


def write_recorder(topic: str, msgtype: str, msgs: Payloads) -> Callable[[Path], None]:
    def fn(d: Path) -> None:
        bag = BagRecorder(d / "bag", {topic: msgtype}, compression="none")  # like the anchors
        for t, data in msgs:
            bag.write(topic, t, data)
        bag.close()

    return fn


def write_rosbags(topic: str, msgtype: str, msgs: Payloads) -> Callable[[Path], None]:
    def fn(d: Path) -> None:
        w = RosbagsWriter(d / "bag", version=9, storage_plugin=StoragePlugin.MCAP)
        w.open()
        conn = w.add_connection(topic, msgtype, typestore=TYPESTORE)
        for t, data in msgs:
            w.write(conn, t, data)
        w.close()

    return fn


def write_mcap(topic: str, msgtype: str, msgs: Payloads) -> Callable[[Path], None]:
    text, _ = TYPESTORE.generate_msgdef(msgtype, ros_version=2)

    def fn(d: Path) -> None:
        with open(d / "plain.mcap", "wb") as f:
            w = McapWriter(f, chunk_size=1 << 20, compression=CompressionType.NONE)
            w.start(profile="ros2", library="bench")
            sid = w.register_schema(msgtype, "ros2msg", text.encode())
            cid = w.register_channel(topic, "cdr", sid)
            for t, data in msgs:
                w.add_message(cid, t, data, t)
            w.finish()  # type: ignore[no-untyped-call]

    return fn


def trim_only(msgtype: str, msgs: Payloads) -> Callable[[], None]:
    def run() -> None:
        for _, data in msgs:
            cdr_exact(data, msgtype)

    return run


def top_costs(fn: Callable[[], None], n: int) -> str:
    prof = cProfile.Profile()
    prof.enable()
    fn()
    prof.disable()
    s = io.StringIO()
    pstats.Stats(prof, stream=s).sort_stats("tottime").print_stats(n)
    lines = [ln for ln in s.getvalue().splitlines() if ln.strip()]
    start = next(i for i, ln in enumerate(lines) if ln.lstrip().startswith("ncalls"))
    keep = [lines[start - 3], *lines[start:]]  # "N function calls in T seconds" + the table
    return "\n".join(ln.replace(str(Path(sys.prefix)), "<venv>") for ln in keep)


def main() -> None:
    quick = "--quick" in sys.argv
    repeat = 2 if quick else 5
    big, small = (60, 5000) if quick else (200, 20000)
    sets = [
        ("step_times", "/winder/step_times", "std_msgs/msg/Int64MultiArray", step_time_chunks(big)),
        ("joint_states", "/winder/joint_states", "sensor_msgs/msg/JointState", joint_states(small)),
        ("clock", "/clock", "rosgraph_msgs/msg/Clock", clocks(small)),
    ]
    rows = []
    for label, topic, msgtype, msgs in sets:
        mb = sum(len(d) for _, d in msgs) / 1e6
        writers = [write_mcap(topic, msgtype, msgs), write_recorder(topic, msgtype, msgs)]
        writers.append(write_rosbags(topic, msgtype, msgs))
        best = [float("inf")] * len(writers)
        for _ in range(repeat):  # interleaved: the machine's noise hits all three alike
            for i, w in enumerate(writers):
                best[i] = min(best[i], best_in_dir(w, 1))
        t_mcap, t_rec, t_rb = best
        t_trim = best_of(trim_only(msgtype, msgs), repeat)
        n = len(msgs)
        rows.append(
            [
                label,
                n,
                f"{mb / n * 1e3:7.2f}",
                f"{mb / t_mcap:8.1f}",
                f"{mb / t_rec:8.1f}",
                f"{t_mcap / t_rec:5.2f}",
                f"{t_rec / n * 1e6:7.1f}",
                f"{t_mcap / n * 1e6:7.1f}",
                f"{t_rb / n * 1e6:7.1f}",
                f"{t_trim / n * 1e6:7.1f}",
            ]
        )
    print("Bag writing: winder BagRecorder vs mcap.writer.Writer (no compression) on the same CDR payloads")
    print(
        table(
            ["messages", "count", "kB each", "mcap MB/s", "BagRecorder MB/s", "speed / mcap",
             "BagRecorder us/msg", "mcap us/msg", "rosbags Writer us/msg", "cdr_exact alone us/msg"],
            rows,
        )
    )  # fmt: skip
    print("target: none set; the ratio speed / mcap is what to watch (1.0 = as fast as mcap)")

    for label, topic, msgtype, msgs in sets[:2]:
        print(f"\nwhere BagRecorder's time goes, {label} (cProfile, top by own time)")
        print(top_costs(once_in_dir(write_recorder(topic, msgtype, msgs)), 10))


if __name__ == "__main__":
    t0 = time.perf_counter()
    main()
    print(f"\n({time.perf_counter() - t0:.0f} s)")
