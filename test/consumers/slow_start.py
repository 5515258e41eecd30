"""The sim node with a slow run set-up: its ``begin`` hook takes
``SETUP_S`` s of wall time before the run is on, as a sim node's plan and
bag took on a host that started eight cells at once (docs/BENCHMARKS.md).
Steps keep arriving meanwhile; test_faults.py checks that the stall watch
counts from the end of the set-up and reports no stall.

The environment's ``SLOW_START_S`` sets another set-up time (test_under_load.py
gives 12 s: longer than the profile node's MODE_WAIT, so its sim_config of
the run comes late).

    python slow_start.py [--ros-args -p stall_timeout:=1.0 ...]
"""

from __future__ import annotations

import os
import time
from typing import Any

from winder_sim.sim_node import SIM_TOPICS, SimEngine

from winder.contract.params import SIM_SPECS, check_sim
from winder.contract.stream import JobPlan
from winder.ros.consumer import StepConsumer
from winder.ros.spin import spin

#: s the run's set-up takes (longer than the stall_timeout the test gives)
SETUP_S = float(os.environ.get("SLOW_START_S", "3.0"))


class SlowSetUp(SimEngine):
    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object]:
        time.sleep(SETUP_S)  # the slow set-up itself, on purpose: not a wait
        return super().begin(plan, values)


def slow_start() -> StepConsumer:
    return StepConsumer(
        "sim_node", SIM_SPECS, check_sim, SlowSetUp(), hardware_id="winder_sim", topics=SIM_TOPICS
    )


if __name__ == "__main__":
    spin(slow_start)
