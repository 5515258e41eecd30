"""The smallest hardware driver docs/ARCHITECTURE.md promises: a
``StepConsumer`` with only ``execute`` (it takes each row at once, as fast
as possible) and the consumer's own settings. test_stalls.py runs it behind
the real interp and profile nodes.

    python minimal_driver.py [--ros-args -p stall_timeout:=1.0 ...]
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from winder.contract.params import CONSUMER_SPECS, check_consumer
from winder.ros.consumer import StepConsumer
from winder.ros.spin import spin


class MinimalDriver(StepConsumer):
    def __init__(self) -> None:
        super().__init__("minimal_driver", CONSUMER_SPECS, check_consumer, hardware_id="minimal")
        self.start_lifecycle()

    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        self.executed(rows.shape[0])
        self.reached(int(rows[-1, 0]))


if __name__ == "__main__":
    spin(MinimalDriver)
