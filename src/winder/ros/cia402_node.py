"""``cia402_node``: the cell's axes on CiA 402 drives over CANopen, as the
cell's consumer - :class:`winder.drives.Cia402Backend` behind a
:class:`winder.ros.driver.DriverNode` (docs/DRIVES.md)::

    cia402_node --ros-args -p drives_file:=/path/drives.yaml [-p real_time:=false]
    winder run --drives /path/drives.yaml job.yaml

Its parameters, besides the consumer's and the driver node's
(``driver.DRIVER_SPECS``): ``drives_file`` (read once, when the node
starts), ``real_time`` (SYNC at its period; false: as fast as the drives
answer) and ``require_homing``.

**The twin:** a drives file whose bus is python-can's ``virtual`` interface
gets a drive twin (:class:`winder.drives.SimulatedDrive`) for each axis'
node id, served in this process on the same channel: a virtual channel
reaches no other process, so no real drive can be on it. The same file with
``socketcan``/``can0`` drives real ones. A twin cell's run report has each
twin's CiA 402 state and the state it came from (``twin_states``: "SWITCH
ON DISABLED (from QUICK STOP ACTIVE)" is a quick stop ended at rest), and
the drives file's ``twin_fault`` (a test's hook, a virtual bus only:
:mod:`winder.drives.config`) makes one twin fault at the SYNC it names, once,
or the bus fail under the backend (``unplugged``).

**A bring-up that fails** (a drive that does not answer an SDO, a bus that
cannot be opened) is the run's fault, said in the one line of
:meth:`winder.drives.Cia402Backend.fault`: the run closes incomplete before
any of its steps is taken, and the node takes the next run (the bring-up
tried again). A bus that failed is opened again before the next run; while it
cannot be, the node says ``waiting`` with why.

**Homing** runs when the node starts, in a thread of its own, for drives
with homing in the drives file (or every drive with ``require_homing``):
until it is done the node says ``waiting`` with "homing the axes" and takes
no run; a homing that fails is said the same way, and the node takes no run
until it is started again.

A drives file that cannot be used is said in one line in the log and in the
node's ``waiting`` reason; the node stays up and takes no run.
"""

from __future__ import annotations

import threading
from typing import Any, ClassVar

import numpy as np
import numpy.typing as npt

from winder.drives.config import BACKEND_SPECS
from winder.errors import WinderError
from winder.ros.driver import Backend, DriverNode, RunStart
from winder.ros.spin import answer_help, spin
from winder.spec import Spec

__all__ = ["DrivesBackend", "main"]

ABOUT = "The CiA 402 drives over CANopen (winder.drives.Cia402Backend): the drives_file's axes."


class DrivesBackend(Backend):
    """The node's backend: the drives file named by ``drives_file``, its
    twins on a virtual bus, the homing step, then every method passed to
    :class:`winder.drives.Cia402Backend` (see the module doc). canopen is
    loaded with the drives file, not with this module: ``--help`` answers
    without it."""

    specs: ClassVar[dict[str, Spec]] = {
        "drives_file": Spec(
            "drives_file", str, "", "the drives file (YAML: the CAN bus, the SYNC period, a drive per axis)"
        ),
        **BACKEND_SPECS,  # Cia402Backend.specs: real_time, require_homing
    }

    def __init__(self) -> None:
        self.drives: Any = None  # the Cia402Backend, once the drives file is read
        self.refused = ""  # the run's bring-up failed: why, in one line (the run's fault)
        self.twins: list[Any] = []
        self.twin_network: Any = None
        self.unusable = "no drives file (set the parameter drives_file)"
        self.homing: threading.Thread | None = None
        self.homing_failed = ""
        self.log: Any = print

    def load(self, path: str, require_homing: bool) -> None:
        """Read the drives file, start its twins on a virtual bus, start homing."""
        from winder.drives import Cia402Backend, SimulatedDrive, load_drives

        if not path:
            return
        try:
            cfg = load_drives(path)
        except WinderError as exc:
            self.unusable = str(exc)
            return
        lacking = [d.axis for d in cfg.axes if d.homing is None]
        if require_homing and lacking:
            self.unusable = f"require_homing: the drives file {path} has no homing for {', '.join(lacking)}"
            return
        if cfg.bus.interface == "virtual":
            import canopen

            network = canopen.Network()
            network.NOTIFIER_CYCLE = 0.1
            network.connect(interface="virtual", channel=cfg.bus.channel)
            self.twin_network = network
            self.twins = [SimulatedDrive(network, d.node_id) for d in cfg.axes]
            self.simulated = True  # its parts are twin parts, never mixed with real ones
        self.drives = Cia402Backend(cfg)
        if self.twins and cfg.twin_fault is not None:
            axes = [d.axis for d in cfg.axes]
            fault = cfg.twin_fault
            self.arm(fault, self.twins[axes.index(fault.axis)] if fault.axis else None)
        self.drives.log = self.log
        self.unusable = ""
        if len(lacking) < len(cfg.axes):
            self.homing = threading.Thread(target=self.home, name="cia402-homing", daemon=True)
            self.homing.start()

    def arm(self, fault: Any, twin: Any) -> None:
        """``twin_fault``: the twin faults at the ``at_sync``-th SYNC the twins
        see (counted here, after the twins' own handling of it), once; or, for
        ``unplugged``, the backend's bus is shut down under it there (an
        adapter pulled out: python-can raises on its next send and receive)."""
        seen = [0]

        def on_sync(_can_id: int, _data: bytearray, _timestamp: float) -> None:
            seen[0] += 1
            if seen[0] != fault.at_sync:
                return
            if fault.fault == "unplugged":
                self.log(f"twin_fault: the bus is unplugged at SYNC {fault.at_sync}")
                self.drives.network.bus.shutdown()
                return
            self.log(f"twin_fault: the {fault.axis} twin faults ({fault.fault}) at SYNC {fault.at_sync}")
            if fault.fault == "jam":
                twin.jam()
            elif fault.fault == "heartbeat":
                twin.stop_heartbeat()
            elif fault.fault == "sdo":
                twin.hang_sdo()
            else:
                twin.inject_fault(int(fault.fault))

        self.twin_network.subscribe(0x80, on_sync)

    def home(self) -> None:
        try:
            self.drives.home()
        except WinderError as exc:
            self.homing_failed = f"homing failed: {exc}"
            self.log(self.homing_failed)

    def close(self) -> None:
        if self.drives is not None:
            self.drives.close()
        for twin in self.twins:
            twin.stop()
        if self.twin_network is not None:
            self.twin_network.disconnect()

    # -- the Backend methods ----------------------------------------------------------------
    def paces(self, settings: dict[str, Any]) -> bool:
        return bool(settings["real_time"])

    def missing(self) -> str:
        if self.unusable:
            return self.unusable
        if self.homing is not None and self.homing.is_alive():
            return "homing the axes (homing.timeout of the drives file)"
        if self.homing_failed:
            return f"{self.homing_failed} (start the node again to home again)"
        return str(self.drives.missing())

    def begin(self, run: RunStart) -> dict[str, object]:
        """The drives brought up for the run; one that fails is the run's fault
        (:meth:`fault`), not an error of this driver: the node closes the run
        incomplete at its next pump, which comes before any of the run's steps
        (the profile node sends none before this configuration is out)."""
        self.refused = ""
        try:
            return dict(self.drives.begin(run))
        except WinderError as exc:  # a DriveError, a bus that cannot be opened: said, the run not begun
            self.refused = str(self.drives.fault() or exc)
            return {"backend": "cia402", "bring_up": self.refused}

    def write(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        self.drives.write(t_ns, rows)  # nothing goes out after a fault (Cia402Backend)

    def read(self, t_ns: int) -> npt.NDArray[np.float64]:
        return np.asarray(self.drives.read(t_ns), float)

    def fault(self) -> str:
        if self.drives is None:
            return ""
        return self.refused or str(self.drives.fault())

    def status(self) -> dict[str, object]:
        status = dict(self.drives.status()) if self.drives is not None else {}
        if self.twins:  # what the twins say of themselves, beside what the master read of them
            axes = [d.axis for d in self.drives.cfg.axes]
            status["twin_states"] = {
                axis: f"{twin.state} (from {twin.came_from})"
                for axis, twin in zip(axes, self.twins, strict=True)
            }
        return status

    def end(self) -> None:
        if self.drives is not None:
            self.drives.end()

    def estop(self) -> None:
        """The drives' quick stop, then disable (:meth:`winder.drives.Cia402Backend.estop`)."""
        if self.drives is not None and self.drives.drives:
            self.drives.estop()


class Cia402Node(DriverNode):
    """The driver node around :class:`DrivesBackend`: the drives file read once it is made."""

    def __init__(self) -> None:
        backend = DrivesBackend()
        super().__init__(backend, "cia402_node", "winder_cia402")
        backend.log = self.get_logger().info
        path = str(self.get_parameter("drives_file").value)
        backend.load(path, bool(self.get_parameter("require_homing").value))
        if backend.unusable:
            self.get_logger().error(backend.unusable)
        self.drives_backend = backend

    def shutdown(self) -> None:
        try:
            super().shutdown()
        finally:
            self.drives_backend.close()


def main(args: list[str] | None = None) -> None:
    parameters = DriverNode.parameters(DrivesBackend)
    if not answer_help("cia402_node", ABOUT, parameters, args):
        spin(Cia402Node, args)


if __name__ == "__main__":
    main()
