"""A drive whose driver has a bug, or whose axes do not follow: on the run
given by ``--fail-run N`` (counted from 1) ``--fail`` picks what goes wrong,
then it works again. test_driver_node.py runs it behind the real interp and
profile nodes.

* ``write``: write() raises;
* ``begin``: begin() raises;
* ``json``: begin() returns a configuration JSON cannot hold;
* ``nan``: read() says NaN;
* ``none``: read() returns None;
* ``text``: read() returns numbers as text;
* ``exit``: write() calls sys.exit(3) (SystemExit);
* ``interrupt``: write() raises KeyboardInterrupt;
* ``hang``: begin() does not return for HANG_S s (a drive that does not answer);
* ``lines``: fault() says what is wrong in three lines;
* ``stuck``: the axes stop following (read() holds the run's start).

    python faulty_drive.py --fail write --fail-run 1 [--ros-args ...]
"""

from __future__ import annotations

import sys
import time

import numpy as np
import numpy.typing as npt

from winder.ros.driver import Backend, DriverNode, RunStart
from winder.ros.spin import spin

#: s a hanging begin() takes (the test gives the node a begin_timeout below it)
HANG_S = 4.0


class FaultyDrive(Backend):
    def __init__(self, fail: str, fail_run: int) -> None:
        self.fail, self.fail_run, self.runs = fail, fail_run, 0
        self.position = np.zeros(3)

    def failing(self, what: str) -> bool:
        return self.fail == what and self.runs == self.fail_run

    def begin(self, run: RunStart) -> dict[str, object]:
        self.runs += 1
        self.position = run.start.astype(float)
        if self.failing("begin"):
            raise OSError("/dev/ttyDRIVE: no such device")
        if self.failing("hang"):
            time.sleep(HANG_S)  # the drive not answering, on purpose: not a wait
        return {"port": object()} if self.failing("json") else {"port": "/dev/ttyDRIVE"}

    def write(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        if self.failing("write"):
            raise RuntimeError("the drive's buffer index ran past its end")
        if self.failing("exit"):
            sys.exit(3)
        if self.failing("interrupt"):
            raise KeyboardInterrupt
        if not self.failing("stuck"):
            self.position = rows[-1, 2:].astype(float)

    def read(self, t_ns: int) -> npt.NDArray[np.float64]:
        if self.failing("none"):
            return None  # type: ignore[return-value]
        if self.failing("text"):
            return ["0", "0", "0"]  # type: ignore[return-value]
        return np.full(3, np.nan) if self.failing("nan") else self.position

    def fault(self) -> str:
        if self.failing("lines"):
            return "fork drive: following error\n  at 0x3f20: 3000 counts\n  drive disabled"
        return ""


if __name__ == "__main__":
    argv = sys.argv[1:]
    fail = argv[argv.index("--fail") + 1] if "--fail" in argv else ""
    fail_run = int(argv[argv.index("--fail-run") + 1]) if "--fail-run" in argv else 0
    spin(lambda: DriverNode(FaultyDrive(fail, fail_run), "faulty_drive"))
