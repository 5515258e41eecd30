"""A line controller for a winder cell in a few lines of rclpy: start the job
set in the cell, follow its run by id on /diagnostics, report how it ended.
Standard messages and services only (std_srvs, diagnostic_msgs).

    ROS_DOMAIN_ID=42 python docs/cell_controller.py [NAMESPACE]

Exit status 0 if the run ended done, 1 otherwise.
"""

import re
import sys

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from std_srvs.srv import Trigger


def main() -> int:
    ns = (sys.argv[1] if len(sys.argv) > 1 else "").strip("/")
    sim_status = f"{ns}/sim_node: job" if ns else "sim_node: job"
    rclpy.init()
    node = rclpy.create_node("line_controller")
    run_id, ending = "", {}

    def on_status(msg: DiagnosticArray) -> None:
        for st in msg.status:
            values = {kv.key: kv.value for kv in st.values}
            # every node's job status carries state, job_id, run_id, steps_done, steps_total, progress
            mine = st.name == sim_status and run_id and values["run_id"] == run_id
            if mine and values["state"] in ("done", "aborted", "incomplete"):
                ending.update(values)

    node.create_subscription(DiagnosticArray, "/diagnostics", on_status, 10)
    start = node.create_client(Trigger, f"/{ns}/interp_node/start" if ns else "/interp_node/start")
    start.wait_for_service()
    while True:  # "not ready": the consumer or the profile node is still connecting
        future = start.call_async(Trigger.Request())
        rclpy.spin_until_future_complete(node, future)
        reply = future.result()
        if reply.success or "not ready" not in reply.message:
            break
        rclpy.spin_once(node, timeout_sec=0.5)
    if not reply.success:
        print(f"start refused: {reply.message}")
        return 1
    run_id = re.match(r"run (\S+) started", reply.message).group(1)
    print(f"started run {run_id}")
    while not ending:
        rclpy.spin_once(node, timeout_sec=0.5)
    steps = f"{ending['steps_done']}/{ending['steps_total']} steps"
    print(f"run {run_id}: {ending['state']}, {steps}, bag {ending['bag']}")
    return 0 if ending["state"] == "done" else 1


if __name__ == "__main__":
    sys.exit(main())
