"""A line controller for a winder cell in a few lines of rclpy: start the job
set in the cell, follow its run by id on /diagnostics, report how it ended.
Standard messages and services only (std_srvs, diagnostic_msgs).

    ROS_DOMAIN_ID=42 python docs/cell_controller.py [NAMESPACE] [TIMEOUT_S]

The run's end is the final report of the cell's step consumer (the sim node,
or a hardware driver in its place, whatever its node name): the job status
whose values say ``role: consumer`` (a consumer that names no role yet: the
one named ``sim_node``). Every wait is bounded (TIMEOUT_S, default 600 s, for
the whole run; 60 s to find the cell): a timeout is one line and exit 2.
Exit status 0 if the run ended done, 1 otherwise.
"""

import re
import sys
import time

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from std_srvs.srv import Trigger


def main() -> int:
    ns = (sys.argv[1] if len(sys.argv) > 1 else "").strip("/")
    timeout = float(sys.argv[2]) if len(sys.argv) > 2 else 600.0
    rclpy.init()
    node = rclpy.create_node("line_controller")
    run_id, ending = "", {}

    def consumer(name: str, values: dict) -> bool:
        """The job status of this cell's step consumer (not a node of a deeper namespace)."""
        node_name = name.split(":", 1)[0]
        here = node_name.rsplit("/", 1)[0] if "/" in node_name else ""
        if here != ns or not name.endswith(": job"):
            return False
        role = values.get("role")
        return role == "consumer" if role else node_name.rsplit("/", 1)[-1] == "sim_node"

    def on_status(msg: DiagnosticArray) -> None:
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            # every node's job status carries state, job_id, run_id, steps_done, steps_total, progress, role
            mine = consumer(st.name, values) and run_id and values.get("run_id") == run_id
            if mine and values.get("state") in ("done", "aborted", "incomplete"):
                ending.update(values)

    def spin_until(done, seconds: float, what: str) -> bool:
        deadline = time.monotonic() + seconds
        while not done():
            if time.monotonic() > deadline:
                print(f"cell_controller: no {what} within {seconds:g} s")
                return False
            rclpy.spin_once(node, timeout_sec=0.1)
        return True

    node.create_subscription(DiagnosticArray, "/diagnostics", on_status, 10)
    start = node.create_client(Trigger, f"/{ns}/interp_node/start" if ns else "/interp_node/start")
    t_end = time.monotonic() + timeout
    if not spin_until(start.service_is_ready, min(60.0, timeout), "interp_node/start service"):
        return 2
    while True:  # "not ready": the consumer or the profile node is still connecting
        future = start.call_async(Trigger.Request())
        if not spin_until(future.done, 10.0, "reply to ~/start"):
            start.remove_pending_request(future)  # a reply lost while the service matched: ask again
            reply = None
        else:
            reply = future.result()
            if reply.success or "not ready" not in reply.message:
                break
        if time.monotonic() > t_end:
            print(f"cell_controller: the cell was not ready within {timeout:g} s")
            return 2
        rclpy.spin_once(node, timeout_sec=0.5)
    if not reply.success:
        print(f"start refused: {reply.message}")
        return 1
    run_id = re.match(r"run (\S+) started", reply.message).group(1)
    print(f"started run {run_id}")
    if not spin_until(lambda: bool(ending), max(t_end - time.monotonic(), 0.0), f"end of run {run_id}"):
        return 2
    steps = f"{ending['steps_done']}/{ending['steps_total']} steps"
    print(f"run {run_id}: {ending['state']}, {steps}, bag {ending.get('bag', '')}")
    return 0 if ending["state"] == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
