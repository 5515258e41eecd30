"""``Cia402Backend``: the cell's axes on CiA 402 drives over CANopen (ROS-free).

It is a :class:`winder.ros.driver.Backend` by its methods (``paces``,
``missing``, ``begin``, ``write``, ``read``, ``fault``, ``status``, ``end``)
without importing ROS, so that a node can hold it and a test can drive it
without one. Everything on the bus goes through canopen (SDO, PDO, NMT,
SYNC, EMCY, heartbeat) on python-can; nothing here frames a CAN message.

**Bring-up** (:meth:`begin`), in a commissioning engineer's order: NMT
pre-operational; SDO configuration (0x6502 checked for the mode, the
heartbeat 0x1017, the quick-stop option 0x605A, the following-error window
and time 0x6065/0x6066, the software limits 0x607D, the interpolation period
0x60C2, the homing objects, the mode 0x6060 confirmed in 0x6061, and the
PDOs: RPDO1 controlword + target position, TPDO1 statusword + position
actual, TPDO2 following error actual, all three on every SYNC, every other
PDO disabled); NMT operational; the state machine to OPERATION ENABLED (a
drive in FAULT is reset first, its 0x603F said in words); homing (mode 6)
where the drives file or the ``require_homing`` setting asks for it; back to
the run's mode.

**Homing is a step of its own** (:meth:`home`), before the first run: it may
take minutes (``homing.timeout`` up to 600 s), far past what a run's start
may wait (the node's ``begin_timeout``, at most 10 s, bounded by the profile
node's wait for the run's configuration). A node calls :meth:`home` in a
thread of its own when it starts and takes no run until it has returned
(:mod:`winder.ros.cia402_node`); :meth:`begin` homes only drives not homed
yet (a library user who never called :meth:`home`). A drive keeps its home
until it is powered off.

**The run:** the rows due at each SYNC of the run's grid (``k *
sync_period``) become target positions in counts: the last row due at that
SYNC, so every step counts and none is reordered; a row due between two
SYNCs goes out at the next one. A cycle writes each drive's RPDO, sends the
SYNC, and waits for every drive's TPDOs (as fast as the drives answer). In
profile position (mode 1) a new set-point goes with the bit 4/12 handshake.

**Faults:** an EMCY, the statusword's fault bits, a following error (bit
13), a limit (bit 11), a heartbeat lost, a TPDO or SDO not answered within
``sdo_timeout``, a bus error: each quick-stops every axis (controlword 0x02,
then disable voltage; by PDO where the drive is operational, else by SDO) and
is said in one line by :meth:`fault`, naming the axis, the node, the object
and the reason, and what the stop achieved: a drive that did not answer it is
named, a bus that could not carry it is said.

**A bus error** (python-can raised on a send, or in the network's receive
thread: bus-off, the adapter unplugged) is seen at once, also while a cycle
waits for TPDOs. The bus of this backend's own is then opened again at the
next :meth:`connect` (:meth:`missing`, :meth:`begin`): the next run brings the
drives up on it afresh; while it cannot be opened, :meth:`missing` says why.
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, ClassVar, Protocol

import can
import canopen
import numpy as np
import numpy.typing as npt
from canopen.emcy import EmcyError
from canopen.pdo import PdoMap
from canopen.pdo.base import PdoBase, PdoVariable
from canopen.sdo.exceptions import SdoAbortedError, SdoCommunicationError

from winder.drives.config import BACKEND_SPECS, AxisDrive, DrivesConfig, load_drives, period_object
from winder.errors import UnavailableError, WinderError
from winder.spec import Spec

__all__ = ["Cia402Backend", "DriveError", "error_words", "state_of"]

#: statusword (mask, value) of each CiA 402 state, in canopen's BaseNode402 order
STATES = (
    ("NOT READY TO SWITCH ON", 0x4F, 0x00),
    ("SWITCH ON DISABLED", 0x4F, 0x40),
    ("READY TO SWITCH ON", 0x6F, 0x21),
    ("SWITCHED ON", 0x6F, 0x23),
    ("OPERATION ENABLED", 0x6F, 0x27),
    ("FAULT", 0x4F, 0x08),
    ("FAULT REACTION ACTIVE", 0x4F, 0x0F),
    ("QUICK STOP ACTIVE", 0x6F, 0x07),
)
#: the controlword that leads from a state towards OPERATION ENABLED
TOWARDS_ENABLED = {
    "SWITCH ON DISABLED": 0x06,
    "READY TO SWITCH ON": 0x07,
    "SWITCHED ON": 0x0F,
    "OPERATION ENABLED": 0x0F,
    "QUICK STOP ACTIVE": 0x00,
}
#: EMCY / 0x603F codes a drive reports, in words (CiA 402 annex); others by their class (CiA 301)
ERROR_WORDS = {
    0x2310: "continuous overcurrent",
    0x2320: "short circuit at the outputs",
    0x3210: "DC link overvoltage",
    0x3220: "DC link undervoltage",
    0x4210: "drive temperature too high",
    0x5441: "safe torque off",
    0x7305: "incremental encoder fault",
    0x7320: "position sensor fault",
    0x8130: "heartbeat or life guard error",
    0x8611: "following error",
    0x8612: "reference limit",
    0xFF00: "device specific",
}
#: how long a state change or a quick stop may take, in SYNC cycles of the drive's time at most
STATE_CYCLES = 250
STATE_SECONDS = 2.0


def error_words(code: int) -> str:
    """``0x8611 (following error)``: an error code and what it means."""
    words = ERROR_WORDS.get(code) or EmcyError(code, 0, b"", 0.0).get_desc() or "unknown"
    return f"0x{code:04X} ({words.lower()})"


def state_of(statusword: int) -> str:
    """The CiA 402 state a statusword says."""
    for name, mask, value in STATES:
        if statusword & mask == value:
            return name
    return "UNKNOWN"


class DriveError(WinderError):
    """A drive or the bus failed; the message is the one line said for it."""


class _BusWatch(can.Listener):
    """A listener of the network's receive thread for its errors only: python-can
    raised in ``recv`` (the adapter unplugged, the bus closed). The backend is told
    at once, and the thread tries again at its network's cycle, until the bus is
    closed: without a listener that takes the error the thread would end with a
    traceback on stderr; one that took it and returned would spin on it."""

    def __init__(self, told: Callable[[Exception], None], cycle: float = 0.1) -> None:
        self.told = told
        self.cycle = cycle

    def on_message_received(self, msg: can.Message) -> None:
        return None  # the network's own listener takes the frames

    def on_error(self, exc: Exception) -> None:
        self.told(exc)
        time.sleep(self.cycle)


class RunLike(Protocol):
    """What :meth:`Cia402Backend.begin` reads of :class:`winder.ros.driver.RunStart`."""

    axes: Sequence[Any]
    joint_step: Sequence[float]
    start: npt.NDArray[np.int64]
    settings: dict[str, Any]


class _Drive:
    """One axis' drive as the master sees it: its node, its PDOs and what they said."""

    def __init__(self, cfg: AxisDrive, node: canopen.RemoteNode) -> None:
        self.cfg = cfg
        self.node = node
        self.name = f"{cfg.axis} drive (node {cfg.node_id})"
        self.statusword = 0
        self.position = 0
        self.following = 0
        self.got = [0, 0]  # TPDO1, TPDO2 received since the counts were reset
        self.heartbeat_at = 0.0  # monotonic time of the last heartbeat (0: none yet)
        self.emcy: list[int] = []  # EMCY codes received (0: an error reset)
        self.controlword = 0
        self.target = 0
        self.operational = False  # NMT operational, as last commanded: its PDOs are taken
        self.rpdo: PdoMap | None = None
        self.cw_var: PdoVariable | None = None
        self.target_var: PdoVariable | None = None
        # the run: steps -> counts
        self.counts_per_step = 1.0
        self.origin = 0
        self.command = 0  # the target of the run (counts), last sent
        self.pp_pending = False  # PP: a set-point sent, its acknowledge awaited

    def counts(self, step: float) -> int:
        return self.origin + self.cfg.direction * round(step * self.counts_per_step)

    def steps(self, counts: float) -> float:
        return (counts - self.origin) * self.cfg.direction / self.counts_per_step

    @property
    def state(self) -> str:
        return state_of(self.statusword)


class Cia402Backend:
    """The cell's axes on CiA 402 drives (see the module doc). ``drives``: a
    drives file or its checked configuration (checked here, before any bus
    is opened); ``network``: a connected canopen network to use instead of
    opening the file's bus (the caller keeps it)."""

    #: real drives (its parts are real parts); a caller that serves twins on its bus says otherwise
    simulated: bool = False
    specs: ClassVar[dict[str, Spec]] = BACKEND_SPECS

    def __init__(self, drives: DrivesConfig | str | Path, network: canopen.Network | None = None) -> None:
        self.cfg = drives if isinstance(drives, DrivesConfig) else load_drives(drives)
        self.period_ns = round(self.cfg.sync_period * 1e9)
        self.network = network
        self.own_network = network is None
        self.drives: list[_Drive] = []
        self.cond = threading.Condition()
        self.syncs = 0  # SYNCs sent since the TPDO counts were reset
        self.total_syncs = 0
        self.failed = ""  # the run's fault, one line
        self.running = False
        self.paced = True
        self.next_sync_ns = 0
        self.pending: list[npt.NDArray[np.int64]] = []
        self.log: Callable[[str], None] = lambda _text: None  # a node sets it to its logger
        self.last_sync_wall = 0.0
        self.silent: set[_Drive] = set()  # drives that stopped answering during a stop
        self.homed = False  # every drive with homing in the drives file has been homed
        self.homing_now = False  # home() runs (in its caller's thread)
        self.stop_asked = ""  # an emergency stop asked while homing: the homing loop stops on it
        #: the bus failed (python-can raised: bus-off, the adapter unplugged), in one line: the
        #: next connect() opens it again
        self.bus_lost = ""
        self.watch = _BusWatch(self._on_bus_error)

    # -- the bus -------------------------------------------------------------------------
    def connect(self) -> None:
        """Open the bus (if this backend owns it) and add the drives' nodes; a bus
        that failed since is closed and opened again (see the module doc)."""
        if self.drives and not self.bus_lost:
            return
        if self.drives:
            self.log(f"{self.bus_lost}: the bus is opened again")
            self.close()
        self.bus_lost = ""
        if self.network is None:
            network = canopen.Network()
            network.NOTIFIER_CYCLE = 0.1  # close() waits for the receive thread at most this long
            try:
                network.connect(**self.cfg.bus.kwargs())
            except Exception as exc:  # python-can raises CanError, OSError, ValueError... per adapter
                bus = self.cfg.bus
                raise UnavailableError(
                    f"bus {bus.interface} {bus.channel}: cannot be opened: {_one_line(exc)}"
                ) from None
            self.network = network
        notifier = self.network.notifier
        if notifier is not None and self.watch not in notifier.listeners:
            notifier.add_listener(self.watch)
        for cfg in self.cfg.axes:
            node = canopen.RemoteNode(cfg.node_id, cfg.eds)
            self.network.add_node(node)
            node.sdo.RESPONSE_TIMEOUT = self.cfg.sdo_timeout
            drive = _Drive(cfg, node)
            node.emcy.add_callback(functools.partial(self._on_emcy, drive))
            node.nmt.add_heartbeat_callback(functools.partial(self._on_heartbeat, drive))
            self.drives.append(drive)

    def close(self) -> None:
        """Leave the bus: the nodes removed, the bus closed if this backend opened it."""
        if self.network is None:
            return
        for drive in self.drives:
            for pdo in (*_maps(drive.node.tpdo), *_maps(drive.node.rpdo)):
                if pdo.cob_id is not None and pdo.on_message in self.network.subscribers.get(pdo.cob_id, []):
                    self.network.unsubscribe(pdo.cob_id, pdo.on_message)
            if drive.cfg.node_id in self.network:
                del self.network[drive.cfg.node_id]
        self.drives = []
        notifier = self.network.notifier
        if notifier is not None and self.watch in notifier.listeners:
            notifier.remove_listener(self.watch)
        if self.own_network:
            # a bus that failed raises its error again in the network's check: it was said then
            with contextlib.suppress(Exception):
                self.network.disconnect()
            self.network = None

    def _bus_error(self, exc: BaseException) -> DriveError:
        """A bus error (python-can raised on a send), said in one line and kept: the
        bus is opened again at the next connect()."""
        bus = self.cfg.bus
        text = f"bus {bus.interface} {bus.channel}: {_one_line(exc)}"
        with self.cond:
            self.bus_lost = self.bus_lost or text
        return DriveError(text)

    def _on_bus_error(self, exc: Exception) -> None:
        """The network's receive thread failed (:class:`_BusWatch`): a cycle waiting
        for TPDOs hears it at once."""
        self._bus_error(exc)
        with self.cond:
            self.cond.notify_all()

    def _on_emcy(self, drive: _Drive, err: EmcyError) -> None:
        with self.cond:
            drive.emcy.append(err.code)
            self.cond.notify_all()

    def _on_heartbeat(self, drive: _Drive, _state: int) -> None:
        drive.heartbeat_at = time.monotonic()

    def _on_tpdo(self, drive: _Drive, which: int, pdo: PdoMap) -> None:
        with self.cond:
            if which == 0:
                drive.statusword = int(pdo[0].raw)
                drive.position = int(pdo[1].raw)
            else:
                drive.following = int(pdo[0].raw)
            drive.got[which] += 1
            self.cond.notify_all()

    # -- the Backend methods -------------------------------------------------------------
    def paces(self, settings: dict[str, Any]) -> bool:
        return bool(settings.get("real_time", True))

    def missing(self) -> str:
        try:
            self.connect()
        except WinderError as exc:
            return str(exc)
        return ""

    def begin(self, run: RunLike) -> dict[str, object]:
        """Bring the drives up (see the module doc) and map the run's steps to counts."""
        self.failed = ""
        self.running = False
        self.pending = []
        self.silent = set()
        self.paced = self.paces(run.settings)
        self.connect()
        if len(run.axes) != len(self.drives):
            raise DriveError(f"the run has {len(run.axes)} axes, the drives file {len(self.drives)}")
        for drive, step in zip(self.drives, run.joint_step, strict=True):
            cps = float(step) * drive.cfg.counts_per_unit
            if not cps >= 1.0 or not np.isfinite(cps):
                raise DriveError(
                    f"{drive.cfg.axis}: counts_per_unit={drive.cfg.counts_per_unit:g} gives {cps:g} counts "
                    f"per "
                    f"step of {step:g}: must be at least 1 count per step (else steps would be lost)"
                )
            drive.counts_per_step = cps
        homing = [d for d in self.drives if d.cfg.homing is not None]
        if run.settings.get("require_homing", False):
            lacking = [d.cfg.axis for d in self.drives if d.cfg.homing is None]
            if lacking:
                raise DriveError(f"require_homing: the drives file has no homing for {', '.join(lacking)}")
        try:
            self._bring_up()
            if homing and not self.homed:
                self._home(homing)
                self.homed = True
        except DriveError as exc:
            self._stop_all(str(exc))
            raise
        for drive, start in zip(self.drives, run.start.tolist(), strict=True):
            drive.origin = drive.position - drive.cfg.direction * round(start * drive.counts_per_step)
            drive.command = drive.position
            drive.target = drive.position
        self.next_sync_ns = 0
        self.running = True
        return {
            "backend": "cia402",
            "sync_period": self.cfg.sync_period,
            "axes": {
                d.cfg.axis: {
                    "node_id": d.cfg.node_id,
                    "mode": d.cfg.mode,
                    "counts_per_step": d.counts_per_step,
                    "origin_counts": d.origin,
                    "homed": d.cfg.homing is not None,
                }
                for d in self.drives
            },
        }

    def write(self, t_ns: int, rows: npt.NDArray[np.int64]) -> None:
        if len(rows):
            self.pending.append(np.asarray(rows, np.int64))
        self._advance(t_ns)

    def read(self, t_ns: int) -> npt.NDArray[np.float64]:
        self._advance(t_ns)
        return np.array([d.steps(d.position) for d in self.drives], float)

    def fault(self) -> str:
        return self.failed

    def status(self) -> dict[str, object]:
        return {
            "syncs": self.total_syncs,
            "following_error_counts": {d.cfg.axis: d.following for d in self.drives},
        }

    def end(self) -> None:
        """The run closed: the drives are left SWITCHED ON (holding, not following), or stopped."""
        if self.running and not self.failed:
            try:
                self._cycle(0x07)
            except DriveError as exc:
                self._stop_all(str(exc))
        self.running = False
        self.pending = []

    def quick_stop(self, reason: str) -> str:
        """An emergency stop: every axis quick-stopped, then disabled; the run
        faults with ``reason``. What the stop achieved, in words."""
        return self._stop_all(reason)

    def estop(self) -> str:
        """The node's ``~/estop``: :meth:`quick_stop` with the reason "emergency
        stop"; what it achieved, in words ("every axis quick-stopped", or what
        the bus did not let it do). While :meth:`home` runs in another thread,
        its loop stops at its next SYNC and quick-stops there (one thread on
        the bus at a time)."""
        if self.homing_now:
            self.stop_asked = "emergency stop"
            return "every axis quick-stopped at the homing's next SYNC"
        return self.quick_stop("emergency stop")

    def home(self) -> None:
        """Homing as a step of its own (see the module doc): the drives brought
        up, those with homing in the drives file homed, every drive then left
        SWITCHED ON. A failure quick-stops every axis and raises DriveError."""
        self.connect()
        homing = [d for d in self.drives if d.cfg.homing is not None]
        self.failed = ""
        self.stop_asked = ""
        self.homing_now = True
        try:
            self._bring_up()
            if homing:
                self._home(homing)
            self._cycle(0x07)
            self.homed = True
        except DriveError as exc:
            self._stop_all(str(exc))
            raise
        finally:
            self.homing_now = False

    # -- the run -------------------------------------------------------------------------
    def _advance(self, t_ns: int) -> None:
        """Every SYNC of the run's grid up to ``t_ns``: the targets due then, a cycle."""
        if not self.running or self.failed:
            return
        try:
            while self.next_sync_ns <= t_ns:
                due = self.next_sync_ns
                self._take_rows(due)
                if self.paced:
                    self._pace()
                self._cycle(None)
                self.next_sync_ns += self.period_ns
        except DriveError as exc:
            self._stop_all(str(exc))

    def _take_rows(self, due: int) -> None:
        """The targets: the last row due at ``due`` (rows come in time order)."""
        last: npt.NDArray[np.int64] | None = None
        while self.pending:
            block = self.pending[0]
            n = int(np.searchsorted(block[:, 0], due, side="right"))
            if n:
                last = block[n - 1]
            if n < len(block):
                self.pending[0] = block[n:]
                break
            self.pending.pop(0)
        if last is not None:
            for drive, step in zip(self.drives, last[2:].tolist(), strict=True):
                drive.command = drive.counts(step)

    def _pace(self) -> None:
        """A paced run's SYNC at its period on the wall clock (the drives' cycle)."""
        now = time.monotonic()
        wait = self.last_sync_wall + self.cfg.sync_period - now
        if 0 < wait < 1.0:
            time.sleep(wait)
        self.last_sync_wall = max(now, self.last_sync_wall + self.cfg.sync_period)

    def _cycle(self, controlword: int | None) -> None:
        """One SYNC: each drive's RPDO (its controlword, its target), the SYNC,
        every drive's TPDOs; then the checks. ``controlword``: the same for
        every drive, or None for the run's (enable operation, PP's handshake)."""
        for drive in self.drives:
            if controlword is not None:
                drive.controlword = controlword
            elif drive.cfg.mode == 8:
                drive.controlword = 0x0F
                drive.target = drive.command
            else:
                self._pp(drive)
        self._exchange()
        self._check()

    def _pp(self, drive: _Drive) -> None:
        """Profile position: a new set-point with bit 4 (and 5: at once), bit 4 cleared on its acknowledge."""
        if drive.pp_pending:
            if drive.statusword & 0x1000:
                drive.controlword = 0x2F
                drive.pp_pending = False
        elif not drive.statusword & 0x1000 and drive.command != drive.target:
            drive.target = drive.command
            drive.controlword = 0x3F
            drive.pp_pending = True

    def _exchange(self, quiet: bool = False) -> None:
        """RPDOs, SYNC, and every drive's two TPDOs of that SYNC (within sdo_timeout).
        ``quiet`` (a stop): a drive that does not answer is not waited for again."""
        assert self.network is not None
        if self.bus_lost and not quiet:  # no cycle on a bus that failed; a stop is tried all the same
            raise DriveError(self.bus_lost)
        # the drives that take PDOs: a failed bring-up may leave some unmapped, or pre-operational
        mapped = [d for d in self.drives if d.rpdo is not None and d.operational]
        try:
            for drive in mapped:
                assert drive.rpdo is not None and drive.cw_var is not None and drive.target_var is not None
                drive.cw_var.raw = drive.controlword
                drive.target_var.raw = drive.target
                drive.rpdo.transmit()
            self.network.sync.transmit()
            self.network.check()
        except (can.CanError, OSError, RuntimeError) as exc:
            raise self._bus_error(exc) from None
        self.syncs += 1
        self.total_syncs += 1
        end = time.monotonic() + self.cfg.sdo_timeout
        with self.cond:
            while True:
                if self.bus_lost:
                    raise DriveError(self.bus_lost)
                late = [d for d in mapped if min(d.got) < self.syncs and d not in self.silent]
                if not late or (not quiet and any(any(d.emcy) for d in self.drives)):
                    return  # an EMCY is said at once (the checks); a stop waits for every answer
                left = end - time.monotonic()
                if left <= 0:
                    break
                self.cond.wait(left)
        if quiet:
            self.silent.update(late)
            return
        d = late[0]
        which = "TPDO1 (0x6041, 0x6064)" if d.got[0] < self.syncs else "TPDO2 (0x60F4)"
        raise DriveError(f"{d.name}: no {which} after SYNC within {self.cfg.sdo_timeout:g} s (sdo_timeout)")

    def _check(self) -> None:
        """The faults a cycle can show (see the module doc)."""
        now = time.monotonic()
        for d in self.drives:
            codes = [c for c in d.emcy if c]
            if codes:
                raise DriveError(f"{d.name}: EMCY {error_words(codes[0])}")
            if d.state in ("FAULT", "FAULT REACTION ACTIVE"):
                raise DriveError(f"{d.name}: statusword 0x{d.statusword:04X} says {d.state}{self._code(d)}")
            if d.state == "OPERATION ENABLED" and d.cfg.mode in (1, 8) and d.statusword & 0x2000:
                raise DriveError(
                    f"{d.name}: following error (statusword bit 13): {d.following} counts, "
                    f"window 0x6065 = {d.cfg.following_window}"
                )
            if d.statusword & 0x0800:
                raise DriveError(
                    f"{d.name}: internal limit active (statusword bit 11): target {d.target} outside "
                    f"the software limits 0x607D {d.cfg.limits}"
                )
            timeout = d.cfg.heartbeat_timeout / 1000.0
            if d.cfg.heartbeat_producer and d.heartbeat_at and now - d.heartbeat_at > timeout:
                raise DriveError(
                    f"{d.name}: heartbeat lost (none for {now - d.heartbeat_at:.3g} s, timeout {timeout:g} s)"
                )

    def _code(self, d: _Drive) -> str:
        try:
            return f", 0x603F = {error_words(int(d.node.sdo[0x603F].raw))}"
        except Exception:
            return ""

    # -- bring-up --------------------------------------------------------------------------
    def _bring_up(self) -> None:
        for d in self.drives:
            self._nmt(d, "PRE-OPERATIONAL")
        for d in self.drives:
            self._configure(d)
        now = time.monotonic()
        for d in self.drives:
            d.emcy.clear()
            d.got = [0, 0]
            d.heartbeat_at = now  # a heartbeat is due within the timeout from here
            self._nmt(d, "OPERATIONAL")
        self.syncs = 0
        self._enable()

    def _nmt(self, d: _Drive, state: str) -> None:
        """An NMT command to the drive; PDOs reach it only while it is operational."""
        d.operational = False
        try:
            d.node.nmt.state = state
        except (can.CanError, OSError) as exc:
            raise self._bus_error(exc) from None
        d.operational = state == "OPERATIONAL"

    def _sdo(self, d: _Drive, index: int, sub: int | None, value: int | None = None) -> int:
        """Read (``value`` None) or write one object by SDO; a refusal or no answer is a DriveError."""
        what = f"0x{index:04X}" + (f":{sub}" if sub is not None else "")
        try:
            var = d.node.sdo[index] if sub is None else d.node.sdo[index][sub]
            if value is None:
                return int(var.raw)
            var.raw = value
            return value
        except SdoAbortedError as exc:
            doing = f"write of {what} = {value}" if value is not None else f"read of {what}"
            raise DriveError(f"{d.name}: refused the SDO {doing}: {_one_line(exc)}") from None
        except SdoCommunicationError:
            doing = "write of" if value is not None else "read of"
            raise DriveError(
                f"{d.name}: SDO {doing} {what} not answered within {self.cfg.sdo_timeout:g} s (sdo_timeout)"
            ) from None
        except KeyError:
            raise DriveError(f"{d.name}: its EDS has no object {what}") from None
        except (can.CanError, OSError) as exc:
            raise self._bus_error(exc) from None

    def _configure(self, d: _Drive) -> None:
        """SDO configuration, the drive pre-operational (see the module doc)."""
        cfg = d.cfg
        supported = self._sdo(d, 0x6502, None)
        need = {cfg.mode: 0x80 if cfg.mode == 8 else 0x01}
        if cfg.homing is not None:
            need[6] = 0x20
        for mode, bit in need.items():
            if not supported & bit:
                raise DriveError(
                    f"{d.name}: mode {mode} is not among its supported modes (0x6502 = 0x{supported:X})"
                )
        self._sdo(d, 0x1017, None, cfg.heartbeat_producer)
        self._sdo(d, 0x605A, None, cfg.quick_stop_option)
        self._sdo(d, 0x6065, None, cfg.following_window)
        self._sdo(d, 0x6066, None, cfg.following_time)
        if cfg.limits is not None:
            self._sdo(d, 0x607D, 1, cfg.limits[0])
            self._sdo(d, 0x607D, 2, cfg.limits[1])
        if cfg.position_window is not None:
            self._sdo(d, 0x6067, None, cfg.position_window)
        for index, value in cfg.profile.items():
            self._sdo(d, index, None, value)
        if cfg.mode == 8:
            value, exponent = period_object(self.cfg.sync_period) or (4, -3)
            self._sdo(d, 0x60C2, 1, value)
            self._sdo(d, 0x60C2, 2, exponent)
        if cfg.homing is not None:
            h = cfg.homing
            self._sdo(d, 0x6098, None, h.method)
            self._sdo(d, 0x607C, None, h.offset)
            self._sdo(d, 0x6099, 1, h.switch_speed)
            self._sdo(d, 0x6099, 2, h.zero_speed)
            self._sdo(d, 0x609A, None, h.acceleration)
        self._set_mode(d, cfg.mode)
        self._map_pdos(d)
        # its state and where it stands, before its first RPDO: a drive enabled already (the
        # bus opened again, the master started again) is sent its own position, not a stale one
        d.statusword = self._sdo(d, 0x6041, None)
        d.position = self._sdo(d, 0x6064, None)
        d.target = d.position

    def _set_mode(self, d: _Drive, mode: int) -> None:
        self._sdo(d, 0x6060, None, mode)
        end = time.monotonic() + STATE_SECONDS
        while (shown := self._sdo(d, 0x6061, None)) != mode:
            if time.monotonic() > end:
                raise DriveError(f"{d.name}: 0x6061 = {shown} after 0x6060 = {mode} (the mode was not taken)")

    def _map_pdos(self, d: _Drive) -> None:
        """RPDO1 controlword + target, TPDO1 statusword + position, TPDO2 following error,
        each on every SYNC; every other PDO of the drive disabled."""
        node = d.node
        try:
            for maps, ours in ((_maps(node.rpdo), 1), (_maps(node.tpdo), 2)):
                for pdo in maps[ours:]:  # RPDO1; TPDO1 and 2 are mapped below
                    cob = self._sdo(d, pdo.com_record.od.index, 1)
                    if not cob & 0x80000000:
                        self._sdo(d, pdo.com_record.od.index, 1, cob | 0x80000000)
                    pdo.enabled = False
            rpdo = node.rpdo[1]
            rpdo.clear()
            cw = rpdo.add_variable(0x6040)
            target = rpdo.add_variable(0x607A)
            rpdo.cob_id = rpdo.predefined_cob_id
            rpdo.trans_type = 1
            rpdo.enabled = True
            rpdo.save()
            for number, objects in ((1, (0x6041, 0x6064)), (2, (0x60F4,))):
                tpdo = node.tpdo[number]
                tpdo.clear()
                for index in objects:
                    tpdo.add_variable(index)
                tpdo.cob_id = tpdo.predefined_cob_id
                tpdo.trans_type = 1
                tpdo.enabled = True
                tpdo.save()
                if not tpdo.callbacks:
                    tpdo.add_callback(lambda pdo, d=d, n=number - 1: self._on_tpdo(d, n, pdo))
        except SdoAbortedError as exc:
            raise DriveError(f"{d.name}: refused its PDO mapping: {_one_line(exc)}") from None
        except SdoCommunicationError:
            raise DriveError(
                f"{d.name}: SDO of its PDO mapping not answered within {self.cfg.sdo_timeout:g} s "
                "(sdo_timeout)"
            ) from None
        except (can.CanError, OSError) as exc:
            raise self._bus_error(exc) from None
        if cw is None or target is None:
            raise DriveError(f"{d.name}: its EDS cannot map 0x6040 and 0x607A")
        d.rpdo, d.cw_var, d.target_var = rpdo, cw, target

    def _enable(self) -> None:
        """The state machine of every drive to OPERATION ENABLED (a drive in FAULT reset first)."""
        said: set[int] = set()
        end = time.monotonic() + STATE_SECONDS
        for _ in range(STATE_CYCLES):
            for d in self.drives:
                state = d.state
                if state == "FAULT":
                    if d.cfg.node_id not in said:
                        said.add(d.cfg.node_id)
                        self.log(f"{d.name} is in FAULT{self._code(d)}: fault reset")
                    d.controlword = 0x80 if d.controlword != 0x80 else 0x00
                else:
                    d.controlword = TOWARDS_ENABLED.get(state, 0x00)
                d.target = d.position  # CSP: enabled where it stands
            self._exchange()
            for d in self.drives:  # a drive that faults while being enabled (a reset's EMCY 0 is fine)
                codes = [c for c in d.emcy if c]
                if codes:
                    raise DriveError(f"{d.name}: EMCY {error_words(codes[0])} while being enabled")
            if all(d.state == "OPERATION ENABLED" for d in self.drives):
                self._check()
                return
            if time.monotonic() > end:
                break
        stuck = [d for d in self.drives if d.state != "OPERATION ENABLED"]
        d = stuck[0]
        raise DriveError(
            f"{d.name}: not OPERATION ENABLED after {STATE_SECONDS:g} s: statusword 0x{d.statusword:04X} "
            f"({d.state}){self._code(d) if d.state == 'FAULT' else ''}"
        )

    def _home(self, drives: list[_Drive]) -> None:
        """Homing (mode 6) of these drives, the others holding; then back to the run's mode."""
        for d in drives:
            self._set_mode(d, 6)
        timeout = max(d.cfg.homing.timeout for d in drives if d.cfg.homing is not None)
        end = time.monotonic() + timeout
        homing = set(id(d) for d in drives)
        started: set[int] = set()
        while True:
            for d in self.drives:
                if id(d) in homing:
                    d.controlword = 0x1F if id(d) in started else 0x0F
                else:
                    d.controlword = 0x0F
                    if d.cfg.mode == 8:
                        d.target = d.position
            self._exchange()
            self._check()
            if self.stop_asked:
                raise DriveError(self.stop_asked)
            done = True
            for d in drives:
                if id(d) not in started:
                    started.add(id(d))
                    done = False
                    continue
                bits = d.statusword & 0x3400
                if bits & 0x2000:
                    raise DriveError(
                        f"{d.name}: homing method {d.cfg.homing.method if d.cfg.homing else '?'} failed "
                        "(statusword bit 13)"
                    )
                if bits != 0x1400:
                    done = False
            if done:
                break
            if time.monotonic() > end:
                raise DriveError(f"homing not attained within {timeout:g} s (homing.timeout)")
        for d in drives:
            d.controlword = 0x0F
        self._exchange()
        for d in drives:
            self._set_mode(d, d.cfg.mode)
            d.target = d.position
        self._exchange()
        self._check()

    # -- stopping --------------------------------------------------------------------------
    def _stop_all(self, reason: str) -> str:
        """Quick stop of every axis, then disable voltage; ``reason`` becomes the run's
        fault, with what the stop achieved (the first cause stays the fault). What it
        achieved, in words."""
        first = not self.failed
        if first:
            self.failed = reason
        self.running = False
        outcome = self._quick_stop_every_axis(reason)
        if first:
            self.failed = f"{reason}; {outcome}"
            self.log(self.failed)
        return outcome

    def _quick_stop_every_axis(self, reason: str) -> str:
        """Every drive's quick stop (controlword 0x02 until it rests), then disable
        voltage (0x00): by PDO where it is operational, by SDO where it is not (a
        bring-up that failed). Best effort: what was achieved, in words."""
        unanswered: list[_Drive] = []
        try:
            for d in self.drives:
                if d.rpdo is not None and d.operational:
                    continue
                for word in (0x02, 0x00):
                    try:
                        d.node.sdo[0x6040].raw = word
                    except (can.CanError, OSError) as exc:
                        raise self._bus_error(exc) from None
                    except Exception:  # an abort, no answer: the drive is named
                        unanswered.append(d)
                        break
            if any(d.rpdo is not None and d.operational for d in self.drives):
                self._quick_stop_by_pdo()
        except DriveError as exc:  # the bus: its error is the stop's
            said = str(exc)
            return "the quick stop could not be completed" + (" on it" if said == reason else f": {said}")
        unanswered += [d for d in self.drives if d in self.silent and d not in unanswered]
        if not unanswered:
            return "every axis quick-stopped"
        names = " and ".join(d.name for d in unanswered)
        return f"every axis quick-stopped but {names}, which did not answer"

    def _quick_stop_by_pdo(self) -> None:
        """The quick stop of the operational drives, SYNC by SYNC until each rests
        (at most STATE_SECONDS), then disable voltage; a drive that does not answer is
        not waited for again (:attr:`silent`)."""
        end = time.monotonic() + STATE_SECONDS
        for _ in range(STATE_CYCLES):
            for d in self.drives:
                d.controlword = 0x02  # quick stop: a drive in OPERATION ENABLED decelerates
                d.target = d.position
            self._exchange(quiet=True)
            resting = all(
                d.state
                in (
                    "SWITCH ON DISABLED",
                    "FAULT",
                    "READY TO SWITCH ON",
                    "SWITCHED ON",
                    "NOT READY TO SWITCH ON",
                )
                or (d.state == "QUICK STOP ACTIVE" and d.statusword & 0x0400)
                for d in self.drives
                if d.rpdo is not None and d.operational and d not in self.silent
            )
            if resting or time.monotonic() > end:
                break
        for d in self.drives:
            d.controlword = 0x00  # disable voltage
        self._exchange(quiet=True)


def _maps(pdos: PdoBase) -> list[PdoMap]:
    """A node's RPDO or TPDO maps, in their order (RPDO1 first)."""
    return [pdos.map[n] for n in sorted(pdos.map)] if pdos.map is not None else []


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text or type(exc).__name__
