"""The sim node with a clock that runs past a resume: the first step chunk
after a pause's rest finds the node's clock ``LEAP_S`` s beyond the chunk's
first step (the samples to there simulated first), as a drive's clock that
went on while the resumed steps were on their way, or the sim node's own
free-running clock under load before issue 40 was fixed. The resumed steps
then come behind its clock; test_under_load.py checks that they are executed
at the clock, counted and reported, never a crash.

    python late_clock.py [--ros-args -p real_time:=true ...]
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
from winder_sim.sim_node import SIM_TOPICS, SimEngine

from winder.contract.params import SIM_SPECS, check_sim
from winder.contract.stream import JobPlan
from winder.ros.chunks import TIMED_CDR
from winder.ros.consumer import StepConsumer
from winder.ros.spin import spin

#: s the clock is beyond the first step after a rest when that step comes
LEAP_S = 1.0


class RestWatch(SimEngine):
    rested = False

    def begin(self, plan: JobPlan, values: dict[str, Any]) -> dict[str, object]:
        self.rested = False  # at rest after a pause: the next chunk is the resume's
        return super().begin(plan, values)

    def work(self) -> None:
        if self.run.at_rest:
            self.rested = True
        super().work()


class LateClock(StepConsumer):
    def __init__(self) -> None:
        self.sim = RestWatch()
        super().__init__(
            "sim_node", SIM_SPECS, check_sim, self.sim, hardware_id="winder_sim", topics=SIM_TOPICS
        )

    def accept(self, raw: bytes) -> npt.NDArray[np.int64] | None:
        if self.sim.rested and self.plan is not None:
            self.sim.rested = False
            try:
                rows = TIMED_CDR.decode(raw)
            except ValueError:  # not a chunk: the base refuses it
                return super().accept(raw)
            if rows.shape[0]:
                self.sim.simulate(None, None, until=int(rows[0, 0]) / 1e9 + LEAP_S)
        return super().accept(raw)


if __name__ == "__main__":
    spin(LateClock)
