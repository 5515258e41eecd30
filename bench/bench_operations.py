"""How soon a pause takes effect in a real-time run.

The three nodes run a long job in real time (look-ahead 50 ms, joint states
at 200 Hz); this process calls the profile node's ``~/pause`` at random
moments (then ``~/resume`` after the axes rest), N times, and reads each
pause's event on winder/control: ``latency_ns`` is the simulated time from
the request (the cell's clock as the profile node last heard it) to the
moment the deceleration starts. The anchor, in the same run: the look-ahead
itself; the bound docs/OPERATING.md states is the look-ahead plus one step
interval at v_max (plus one sample period of clock lag, not in the figure).

    .venv/bin/python bench/bench_operations.py [--quick]   # --quick: 12 pauses, else 60
"""

from __future__ import annotations

import argparse
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import domain as common_domain
from _common import table

from winder.procs import popen

BIN = Path(sys.executable).parent
LOOKAHEAD = 0.05
V_MAX = 2048.0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true")
    n = 12 if ap.parse_args().quick else 60
    import rclpy
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_srvs.srv import Trigger

    from winder_interfaces.msg import ControlEvent

    work = Path(tempfile.mkdtemp(prefix="winder-bench-ops-"))
    domain = common_domain()
    env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    cmds = [
        [str(BIN / "sim_node"), "--ros-args", "-p", f"bag_dir:={work}", "-p", "real_time:=true"],
        [str(BIN / "profile_node"), "--ros-args", "-p", f"lookahead:={LOOKAHEAD}"],
        [str(BIN / "interp_node"), "--ros-args", "-p", "turns_per_layer:=2000", "-p", "poles:=1"],
    ]
    procs = [popen(c, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for c in cmds]
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    rclpy.init(domain_id=domain)
    node = rclpy.create_node("bench_operations")
    events: list[dict[str, object]] = []
    qos = QoSProfile(
        depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
    )
    node.create_subscription(
        ControlEvent,
        "/winder/control",
        lambda m: events.append({"event": m.event, "latency_ns": m.latency_ns, "v": m.v}),
        qos,
    )
    clients = {k: node.create_client(Trigger, f"/profile_node/{k}") for k in ("pause", "resume", "abort")}
    rng = random.Random(7)

    def call(kind: str) -> tuple[bool, str]:
        future = clients[kind].call_async(Trigger.Request())
        t_end = time.monotonic() + 10
        while not future.done() and time.monotonic() < t_end:
            rclpy.spin_once(node, timeout_sec=0.01)
        reply = future.result()
        return (bool(reply.success), str(reply.message)) if reply else (False, "no reply")

    def spin(seconds: float) -> None:
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            rclpy.spin_once(node, timeout_sec=0.01)

    try:
        for c in clients.values():
            while not c.wait_for_service(timeout_sec=1.0):
                pass
        spin(3.0)  # the run starts (autostart) and gets up to speed
        replies = []
        for _ in range(n):
            spin(rng.uniform(0.2, 0.6))  # a random moment of the motion
            t0 = time.monotonic()
            ok, why = call("pause")
            replies.append(time.monotonic() - t0)
            if not ok:
                print(f"pause refused: {why}")
            spin(0.5)  # brake and rest
            call("resume")
        call("abort")
        spin(1.0)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
        for p in procs:
            p.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.wait(timeout=20)
            except subprocess.TimeoutExpired:
                p.kill()
    pauses = [e for e in events if e.get("event") == "pause"]
    lat = np.array([e["latency_ns"] for e in pauses], dtype=float) / 1e6
    # the first step beyond the horizon: one step interval at the speed of the moment
    bound = np.array([LOOKAHEAD + 1.0 / max(float(e["v"]), 1.0) for e in pauses]) * 1e3 + 1e-6
    print(f"{lat.size} live pauses in a real-time run, look-ahead {LOOKAHEAD * 1e3:g} ms (the anchor)")
    rows = [
        (name, f"{x:.2f} ms", f"{x / (LOOKAHEAD * 1e3):.3f}")
        for name, x in (
            ("min", lat.min()),
            ("median", float(np.median(lat))),
            ("95th percentile", float(np.percentile(lat, 95))),
            ("max", lat.max()),
        )
    ]
    print(table(("request -> deceleration starts", "latency", "x look-ahead"), rows))
    print(
        f"bound look-ahead + one step interval at the speed of the moment (>= {1e3 / V_MAX:.2f} ms): "
        f"{int(np.sum(lat <= bound))} of {lat.size} within; "
        f"service round trip (wall) median {np.median(replies) * 1e3:.1f} ms"
    )


if __name__ == "__main__":
    main()
