"""``MockBackend``: a drive that follows its commands, as ros2_control's
``mock_components/GenericSystem`` does - at once, or with a first-order lag
- and the smallest working :class:`winder.ros.driver.Backend` to start a
driver from. Run it as the cell's consumer::

    .venv/bin/python -m winder.ros.mock_backend [--ros-args -p lag:=0.01 -p real_time:=false]

Its parameters, besides the consumer's and the driver node's (``settle_time``,
``begin_timeout``...: ``driver.DRIVER_SPECS``): ``real_time`` (execute each
step at its time, as a drive does; false: every step at once) and ``lag``
(s: the axes follow the commanded position with this time constant; 0: at once).
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from winder.ros.driver import Backend, DriverNode, RunStart
from winder.ros.spin import answer_help, spin
from winder.spec import Spec

__all__ = ["MockBackend", "main"]


class MockBackend(Backend):
    """Axes that go where they are told (see the module doc)."""

    specs: ClassVar[dict[str, Spec]] = {
        "real_time": Spec("real_time", bool, True, "execute each step at its time, as a drive does"),
        "lag": Spec("lag", float, 0.0, "the axes' time constant following a command", "s", 0.0, 10.0),
    }
    simulated = True  # no drive behind it: its parts are not real parts

    def __init__(self) -> None:
        self.command = np.zeros(0)
        self.position = np.zeros(0)
        self.t_ns = 0
        self.lag = 0.0
        self.writes = 0

    def paces(self, settings: dict[str, Any]) -> bool:
        return bool(settings["real_time"])

    def begin(self, run: RunStart) -> dict[str, object]:
        self.command = run.start.astype(float)
        self.position = self.command.copy()
        self.t_ns = 0
        self.lag = float(run.settings["lag"])
        self.writes = 0
        return {"backend": "mock", "lag": self.lag}

    def write(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        """Each row is a step of the command at its own time (the axes follow
        the staircase, not a jump once a tick); they are followed up to ``t_ns``."""
        if self.lag > 0.0:
            for t_row, *pos in rows[:, [0, *range(2, rows.shape[1])]].tolist():
                self.follow(max(int(t_row), self.t_ns))
                self.command = np.array(pos, float)
        else:
            self.command = rows[-1, 2:].astype(float)
        self.follow(t_ns)
        self.writes += 1

    def read(self, t_ns: int) -> npt.NDArray[np.float64]:
        self.follow(t_ns)
        return self.position.copy()

    def follow(self, t_ns: int) -> None:
        """The axes move towards the command held since the last call (exact for a held command)."""
        dt = max(t_ns - self.t_ns, 0) / 1e9
        self.t_ns = max(t_ns, self.t_ns)
        if self.lag <= 0.0:
            self.position = self.command.copy()
        elif dt > 0.0:
            self.position += (self.command - self.position) * -math.expm1(-dt / self.lag)

    def status(self) -> dict[str, object]:
        return {"commands_written": self.writes}


def main(args: list[str] | None = None) -> None:
    about = "The mock drive: a driver node whose axes follow their commands (MockBackend)."
    if not answer_help("python -m winder.ros.mock_backend", about, DriverNode.parameters(MockBackend), args):
        spin(lambda: DriverNode(MockBackend(), "mock_driver", "winder_mock"), args)


if __name__ == "__main__":
    main()
