"""The smallest hardware driver docs/ARCHITECTURE.md promises: a
``StepConsumer`` holding an engine with only ``execute`` (it takes each row at once, as fast
as possible) and the consumer's own settings. test_stalls.py runs it behind
the real interp and profile nodes.

    python minimal_driver.py [--ros-args -p stall_timeout:=1.0 ...]
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from winder.contract.params import CONSUMER_SPECS, check_consumer
from winder.ros.consumer import StepConsumer
from winder.ros.engine import Engine
from winder.ros.spin import spin


class AtOnce(Engine):
    def execute(self, rows: npt.NDArray[np.int64]) -> None:
        self.run.executed(rows.shape[0])
        self.run.reached(int(rows[-1, 0]))


def minimal_driver() -> StepConsumer:
    return StepConsumer("minimal_driver", CONSUMER_SPECS, check_consumer, AtOnce(), hardware_id="minimal")


if __name__ == "__main__":
    spin(minimal_driver)
