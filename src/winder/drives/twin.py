"""``SimulatedDrive``: a CiA 402 drive twin on a CANopen network (ROS-free).

It serves the objects of its EDS (:attr:`SimulatedDrive.EDS`, shipped beside
this module) with canopen's own :class:`canopen.LocalNode` (SDO server, NMT
slave, PDOs, EMCY producer, heartbeat producer): no CAN framing here, only
what a drive does with the objects.

* **The state machine** of CiA 402 (statusword 0x6041 by mask 0x4F/0x6F),
  every transition of the controlword 0x6040 and the automatic ones: NOT
  READY TO SWITCH ON to SWITCH ON DISABLED at start, FAULT REACTION ACTIVE
  to FAULT once the motor is at rest, QUICK STOP ACTIVE to SWITCH ON
  DISABLED at rest where 0x605A says so (options 1 and 2; 5 and 6 stay;
  0 disables at once). A fault reset is the rising edge of bit 7.
* **Modes** 1 (profile position), 6 (homing) and 8 (cyclic synchronous
  position), listed in 0x6502; 0x6061 mirrors 0x6060 only for those.
* **Profile position:** the set-point handshake (bit 4 new set-point, bit 12
  acknowledge, bit 5 change at once, bit 6 relative, bit 8 halt), a
  trapezoid of 0x6081/0x6083/0x6084, bit 10 once within 0x6067 of the target.
* **Cyclic synchronous position:** 0x607A taken at every SYNC, clamped to
  the software limits 0x607D with bit 11 (internal limit active) set.
* **Following error** (PP, CSP, homing): ``|demand - actual|`` over 0x6065
  for longer than 0x6066 ms sets bit 13 and faults with EMCY 0x8611.
* **Homing** methods 35 and 37 (the current position is home) and 19 (the
  home switch on the positive side, against :attr:`home_switch`); 0x607C is
  the position of home.
* **Faults** injected with :meth:`inject_fault` (any EMCY code),
  :meth:`stop_heartbeat` (the drive goes quiet on 0x700), :meth:`jam`
  (the motor blocked: a following error, by the monitoring above) and
  :meth:`hang_sdo` (its SDO server answers nothing until a client aborts).

The motor behind it is winder's stepper model (:class:`winder.axis.StepperAxis`,
the paper's motor unless another is given), followed with the exact linear
response (:class:`winder.axis.LinearTracker`), so the twin and the sim node
move alike. Counts are the model's unit (the response is linear). The drive
steps on SYNC: each SYNC advances its time by the interpolation period 0x60C2,
whatever the wall clock did, so a master that sends SYNC as fast as the drive
answers simulates ahead of real time. At a SYNC the drive samples (position
actual at that instant), monitors, takes the RPDOs and the controlword, and
sends its TPDOs: a command sent before a SYNC shows in that SYNC's TPDO.
"""

from __future__ import annotations

import contextlib
import math
import threading
from importlib import resources
from typing import Any, ClassVar

import canopen
from canopen.objectdictionary import ODVariable
from canopen.pdo import PdoMap
from canopen.pdo.base import PdoBase
from canopen.sdo.constants import REQUEST_ABORTED
from canopen.sdo.exceptions import SdoAbortedError
from canopen.sdo.server import SdoServer

from winder.axis import StepperAxis

__all__ = ["EDS_PATH", "STATUS", "SimulatedDrive"]

#: the twin's EDS: the objects it serves
EDS_PATH = str(resources.files("winder.drives").joinpath("twin.eds"))

#: statusword state bits (mask 0x6F) of each state
STATUS = {
    "NOT READY TO SWITCH ON": 0x00,
    "SWITCH ON DISABLED": 0x40,
    "READY TO SWITCH ON": 0x21,
    "SWITCHED ON": 0x23,
    "OPERATION ENABLED": 0x27,
    "QUICK STOP ACTIVE": 0x07,
    "FAULT REACTION ACTIVE": 0x0F,
    "FAULT": 0x08,
}
#: modes served (0x6502 bits: PP 0x1, HM 0x20, CSP 0x80)
MODE_BITS = {1: 0x01, 6: 0x20, 8: 0x80}
HOMING_METHODS = (19, 35, 37)
FOLLOWING_ERROR = 0x8611
#: SDO abort "value range of parameter exceeded"
ABORT_RANGE = 0x06090030
NMT_OPERATIONAL = 5  # canopen's NMT state code


class _HangingSdoServer(SdoServer):
    """canopen's SDO server, which can hang (:meth:`SimulatedDrive.hang_sdo`):
    while hung it answers no request; a client's abort of a transfer (canopen's
    client sends one when its request times out) frees it."""

    hung = False

    def on_request(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self.hung:
            self.hung = data[0] & 0xE0 != REQUEST_ABORTED
            return
        super().on_request(can_id, data, timestamp)  # type: ignore[no-untyped-call]


class SimulatedDrive:
    """A CiA 402 drive served on ``network`` as node ``node_id`` until :meth:`stop`
    (see the module doc). ``motor``: the stepper behind it (the paper's by
    default); ``home_switch``: the position (counts, from power-on) above
    which the simulated home switch is active."""

    EDS: ClassVar[str] = EDS_PATH

    def __init__(
        self,
        network: canopen.Network,
        node_id: int,
        motor: StepperAxis | None = None,
        home_switch: float = 1000.0,
    ) -> None:
        self.lock = threading.RLock()
        self.network = network
        self.node = canopen.LocalNode(node_id, self.EDS)
        self.sdo_server = _HangingSdoServer(0x600 + node_id, 0x580 + node_id, self.node)  # type: ignore[no-untyped-call]
        self.node.sdo = self.sdo_server
        self.motor = motor or StepperAxis.paper()
        self.tracker = self.motor.linear_tracker()
        self.base = 0.0  # the motor's position when its tracker was made (counts)
        self.jammed = False  # the motor is blocked where it stands (jam())
        self.home_switch = home_switch
        self.state = "NOT READY TO SWITCH ON"
        #: the state before the last one _enter()ed, ", moving" if the demand still moved then
        #: (a node's report says it: a quick stop that ended at rest shows "QUICK STOP ACTIVE")
        self.came_from = ""
        self.t = 0.0  # the drive's time (s): SYNC periods counted
        self.position = 0.0  # the motor, in counts from power-on (the model's theta)
        self.velocity = 0.0  # its speed (counts/s)
        self.demand = 0.0  # the position demand (motor counts), followed by the motor
        self.demand_v = 0.0  # the demand's speed (counts/s)
        self.pending: tuple[float, float] | None = None  # (time, size) of the demand's last change
        self.offset = 0  # position actual = motor + offset (homing moves it)
        self.mode = 0  # 0x6061
        self.controlword = 0
        self.error_code = 0  # 0x603F
        self.limit = False  # bit 11: a target was clamped to 0x607D
        self.following = False  # bit 13 (PP, CSP): the error is over the window
        self.over_since: float | None = None  # since when it is
        self.pp_target: float | None = None  # PP: the set-point taken
        self.pp_ack = False  # bit 12 in PP
        self.halted = False  # PP: bit 8
        self.homing = ""  # "" idle, "search", "back", "settle", "done", "error", "interrupted"
        self.stopping = ""  # "quick" or "fault": decelerating to rest
        self.stop_dec = 0.0
        self.sync_count = 0
        self.last_tpdo: dict[int, bytes] = {}
        self.sync_rpdo: list[PdoMap] = []  # synchronous RPDOs received since the last SYNC
        self.stopped = False
        self.node_id = node_id
        self.node.add_read_callback(self._on_read)  # type: ignore[no-untyped-call]
        self.node.add_write_callback(self._on_write)  # type: ignore[no-untyped-call]
        for rpdo in _maps(self.node.rpdo):
            rpdo.add_callback(self._on_rpdo)
        network.add_node(self.node)
        network.subscribe(0x80, self._on_sync)
        network.subscribe(0, self._on_nmt)
        # power on: boot-up, pre-operational (heartbeat per 0x1017), then the automatic transition 1
        self.node.nmt.state = "INITIALISING"
        self.node.nmt.state = "PRE-OPERATIONAL"
        self.state = "SWITCH ON DISABLED"

    # -- what a test does to the drive -------------------------------------------------
    def stop(self) -> None:
        """The drive leaves the bus: no answer, no heartbeat, no PDO."""
        with self.lock:
            if self.stopped:
                return
            self.stopped = True
            self.node.nmt.stop_heartbeat()  # type: ignore[no-untyped-call]
            self.network.unsubscribe(0x80, self._on_sync)
            self.network.unsubscribe(0, self._on_nmt)
            for pdo in (*_maps(self.node.rpdo), *_maps(self.node.tpdo)):
                self._unsubscribe(pdo)
            del self.network[self.node_id]

    def inject_fault(self, code: int) -> None:
        """A fault of the drive (``code``, an EMCY error code such as 0x2310 overcurrent):
        the fault reaction, the EMCY, 0x603F."""
        with self.lock:
            self._fault(code)
            self._send_event_tpdos()

    def jam(self) -> None:
        """The motor is blocked where it stands (a mechanical jam) until the next
        fault reset: the demand runs away from it, and the drive's following-error
        monitoring (0x6065, 0x6066) faults as configured."""
        with self.lock:
            self.jammed = True
            self.velocity = 0.0

    def stop_heartbeat(self) -> None:
        """The heartbeat stops (a drive that hangs), the rest goes on."""
        with self.lock:
            self.node.nmt.stop_heartbeat()  # type: ignore[no-untyped-call]

    def hang_sdo(self) -> None:
        """Its SDO server hangs: no request is answered (a master's SDO times out)
        until a client aborts a transfer, as canopen's SDO client does when its
        request times out; PDOs, heartbeat and EMCY go on."""
        with self.lock:
            self.sdo_server.hung = True

    @property
    def position_actual(self) -> int:
        """0x6064: the motor's position, counts."""
        return round(self.position) + self.offset

    @property
    def statusword(self) -> int:
        with self.lock:
            return self._statusword()

    # -- the objects ---------------------------------------------------------------------
    def _get(self, index: int, subindex: int = 0) -> Any:
        """The value of a stored object (written, or the EDS default)."""
        obj = self.node.object_dictionary[index]
        var = obj if isinstance(obj, ODVariable) else obj[subindex]
        return var.decode_raw(self.node.get_data(index, subindex))

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        with self.lock:
            if index == 0x6041:
                return self._statusword()
            if index == 0x6064:
                return self.position_actual
            if index == 0x606C:
                return round(self.velocity)
            if index == 0x6061:
                return self.mode
            if index == 0x60F4:
                return round(self.demand - self.position)
            if index == 0x603F:
                return self.error_code
            if index == 0x1001:
                return 0x01 if self.state in ("FAULT", "FAULT REACTION ACTIVE") else 0
            return None

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        """A write by SDO or RPDO, before it is stored: refused values raise an SDO abort."""
        value = od.decode_raw(data)
        with self.lock:
            if index == 0x6098 and value not in HOMING_METHODS:
                raise SdoAbortedError(ABORT_RANGE)
            if index == 0x605A and value not in range(9):
                raise SdoAbortedError(ABORT_RANGE)
            if index == 0x6060:
                # 0x6061 follows only a mode this drive has (0x6502); a switch ends a homing's result
                if value in MODE_BITS and value != self.mode:
                    self.mode = int(value)
                    self.homing = ""
                    self.pp_target = None
                    self.pp_ack = False
            elif index == 0x6040:
                self._controlword(int(value))
            self._send_event_tpdos()

    # -- the state machine ---------------------------------------------------------------
    def _statusword(self) -> int:
        word = STATUS[self.state] | 0x0200  # bit 9 remote
        if self.state in ("READY TO SWITCH ON", "SWITCHED ON", "OPERATION ENABLED", "QUICK STOP ACTIVE"):
            word |= 0x10  # voltage enabled
        if self.limit:
            word |= 0x0800
        enabled = self.state == "OPERATION ENABLED"
        at_rest = self.demand_v == 0.0 and abs(self.demand - self.position) <= self._get(0x6067)
        if self.state == "QUICK STOP ACTIVE" and not self.stopping:
            word |= 0x0400  # at rest
        if self.mode == 1:
            if enabled and (self.pp_target is None or self.pp_target == self.demand) and at_rest:
                word |= 0x0400
            if self.halted and self.demand_v == 0.0:
                word |= 0x0400
            if self.pp_ack:
                word |= 0x1000
            if self.following:
                word |= 0x2000
        elif self.mode == 8:
            if enabled:
                word |= 0x1000  # the drive follows the target
            if self.following:
                word |= 0x2000
        elif self.mode == 6:
            if self.homing in ("done", "interrupted", "error") or (enabled and not self.homing):
                word |= 0x0400
            if self.homing == "done":
                word |= 0x1000
            if self.homing == "error":
                word |= 0x2000
        return word

    def _controlword(self, word: int) -> None:
        before, self.controlword = self.controlword, word
        state = self.state
        if state == "FAULT":
            if word & 0x80 and not before & 0x80:  # transition 15
                if self.jammed:  # freed: the motor is where it was blocked, at rest
                    self.jammed = False
                    self.tracker = self.motor.linear_tracker()
                    self.base, self.demand, self.pending = self.position, self.position, None
                self.error_code = 0
                self.following = False
                self.over_since = None
                self.node.emcy.reset()
                self._enter("SWITCH ON DISABLED")
            return
        if state in ("FAULT REACTION ACTIVE", "NOT READY TO SWITCH ON"):
            return
        disable_voltage = word & 0x82 == 0x00
        quick_stop = word & 0x86 == 0x02
        shutdown = word & 0x87 == 0x06
        switch_on = word & 0x8F == 0x07
        enable = word & 0x8F == 0x0F
        if state == "SWITCH ON DISABLED":
            if shutdown:
                self._enter("READY TO SWITCH ON")  # 2
        elif state == "READY TO SWITCH ON":
            if switch_on:
                self._enter("SWITCHED ON")  # 3
            elif enable:
                self._enter("OPERATION ENABLED")  # 3 and 4 at once
            elif disable_voltage or quick_stop:
                self._enter("SWITCH ON DISABLED")  # 7
        elif state == "SWITCHED ON":
            if enable:
                self._enter("OPERATION ENABLED")  # 4
            elif shutdown:
                self._enter("READY TO SWITCH ON")  # 6
            elif disable_voltage or quick_stop:
                self._enter("SWITCH ON DISABLED")  # 10
        elif state == "OPERATION ENABLED":
            if switch_on:
                self._enter("SWITCHED ON")  # 5
            elif shutdown:
                self._enter("READY TO SWITCH ON")  # 8
            elif disable_voltage:
                self._enter("SWITCH ON DISABLED")  # 9
            elif quick_stop:
                self._quick_stop()  # 11
            else:
                self._mode_bits(before, word)
        elif state == "QUICK STOP ACTIVE":
            if disable_voltage:
                self._enter("SWITCH ON DISABLED")  # 12
            elif enable and not self.stopping and self._get(0x605A) in (5, 6, 7, 8):
                self._enter("OPERATION ENABLED")  # 16

    def _enter(self, state: str) -> None:
        was = self.state
        self.came_from = was if self.demand_v == 0.0 else f"{was}, moving"
        self.state = state
        if state == "OPERATION ENABLED" and was != "QUICK STOP ACTIVE":
            # enabled where it stands: the demand is the motor's position; PP has no set-point yet
            self._hold(round(self.position))
            self.pp_target = None
            self.pp_ack = False
            if self.mode == 6:
                self.homing = ""
        elif state not in ("OPERATION ENABLED", "QUICK STOP ACTIVE", "FAULT REACTION ACTIVE"):
            # the drive function is off: the motor is held (braked) where its demand was
            self._hold(self.demand)
            self.stopping = ""
            self.limit = False
            if self.homing in ("search", "back", "settle"):
                self.homing = "interrupted"

    def _hold(self, at: float) -> None:
        self._set_demand(at)
        self.demand_v = 0.0

    def _set_demand(self, value: float) -> None:
        change = value - self.demand
        if change:
            size = change + (self.pending[1] if self.pending is not None else 0.0)
            self.pending = (self.t, size)
        self.demand = value

    def _quick_stop(self) -> None:
        option = self._get(0x605A)
        if option == 0:
            self._enter("SWITCH ON DISABLED")
            return
        self.state = "QUICK STOP ACTIVE"
        self.stopping = "quick"
        self.stop_dec = float(self._get(0x6084) if option in (1, 5) else self._get(0x6085))
        if self.homing in ("search", "back", "settle"):
            self.homing = "interrupted"

    def _fault(self, code: int) -> None:
        if self.state in ("FAULT", "FAULT REACTION ACTIVE"):
            return
        self.error_code = code
        moving = self.state in ("OPERATION ENABLED", "QUICK STOP ACTIVE")
        self.state = "FAULT REACTION ACTIVE"
        self.node.emcy.send(code, 0x01)
        if moving:
            self.stopping = "fault"
            self.stop_dec = float(self._get(0x6085))
        else:
            self._enter("FAULT")  # 14, at once: nothing to stop
        if self.homing in ("search", "back", "settle"):
            self.homing = "interrupted"

    def _mode_bits(self, before: int, word: int) -> None:
        """Bits 4-8 in OPERATION ENABLED: the PP set-point, the homing start."""
        rising = word & 0x10 and not before & 0x10
        self.halted = bool(word & 0x100) and self.mode == 1
        if self.mode == 1:
            if rising and not self.pp_ack:
                target = float(self._get(0x607A))
                if word & 0x40:  # relative
                    target += (self.pp_target if self.pp_target is not None else self.demand) + self.offset
                self.pp_target = self._clamp(target) - self.offset
                self.pp_ack = True
            elif not word & 0x10:
                self.pp_ack = False
        elif self.mode == 6:
            if rising:
                self._start_homing()
            elif not word & 0x10 and self.homing in ("search", "back", "settle"):
                self.homing = "interrupted"
                self._hold(self.demand)

    def _clamp(self, target: float) -> float:
        low, high = self._get(0x607D, 1), self._get(0x607D, 2)
        clamped = min(max(target, low), high) if low < high else target
        self.limit = clamped != target
        return clamped

    # -- homing ----------------------------------------------------------------------------
    def _start_homing(self) -> None:
        method = self._get(0x6098)
        if method in (35, 37):
            self._home_here(round(self.demand))
            self.homing = "done"
        elif method == 19:
            # the switch is active above home_switch: inactive, search up and come back; active, go down
            self.homing = "back" if self.position >= self.home_switch else "search"
        else:
            self.homing = "error"

    def _home_here(self, motor: float) -> None:
        """The motor position ``motor`` is home: position actual there is 0x607C."""
        self.offset = int(self._get(0x607C)) - round(motor)

    def _homing_step(self, dt: float) -> None:
        switch = self.position >= self.home_switch
        if self.homing == "search":
            if switch:
                self.homing = "back"
            else:
                self._move(float(self._get(0x6099, 1)), dt)
        if self.homing == "back":
            if not switch:
                edge = round(self.demand)
                self._home_here(edge)
                self._hold(edge)
                self.homing = "settle"
            else:
                self._move(-float(self._get(0x6099, 2)), dt)
        if self.homing == "settle" and abs(self.demand - self.position) <= self._get(0x6067):
            self.homing = "done"

    def _move(self, speed: float, dt: float) -> None:
        self.demand_v = speed
        self._set_demand(self.demand + speed * dt)

    # -- SYNC --------------------------------------------------------------------------------
    def _period(self) -> float:
        value, exponent = int(self._get(0x60C2, 1)), int(self._get(0x60C2, 2))
        return max(value, 1) * 10.0**exponent

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        with self.lock:
            if self.stopped or self.node.nmt.state != "OPERATIONAL":
                return
            dt = self._period()
            self.t += dt
            self._sample()
            self._monitor(dt)
            for rpdo in self.sync_rpdo:  # synchronous RPDOs take effect at the SYNC
                self._apply_rpdo(rpdo)
            self.sync_rpdo.clear()
            self._demand_step(dt)
            self.sync_count += 1
            for tpdo, kind in self._tpdos():
                if 1 <= kind <= 240 and self.sync_count % kind == 0:
                    self._send_tpdo(tpdo, always=True)
                elif kind == 0:
                    self._send_tpdo(tpdo, always=False)
            self._send_event_tpdos()

    def _sample(self) -> None:
        """The motor at this SYNC, under the demand held since the last one."""
        times, sizes = ([self.pending[0]], [self.pending[1]]) if self.pending is not None else ([], [])
        self.pending = None
        theta, omega = self.tracker.advance(times, sizes, [self.t])
        if not self.jammed:
            self.position, self.velocity = self.base + float(theta[0]), float(omega[0])

    def _monitor(self, dt: float) -> None:
        window = self._get(0x6065)
        if self.state != "OPERATION ENABLED" or self.mode not in (1, 6, 8) or window == 0xFFFFFFFF:
            self.over_since = None
            return
        over = abs(self.demand - self.position) > window
        if not over:
            self.over_since = None
            self.following = False
            return
        if self.over_since is None:
            self.over_since = self.t - dt
        if self.t - self.over_since > self._get(0x6066) / 1000.0:
            self.following = True
            self._fault(FOLLOWING_ERROR)

    def _demand_step(self, dt: float) -> None:
        """The demand from this SYNC to the next: the run's target, a profile, a stop."""
        if self.state == "FAULT REACTION ACTIVE" or (self.state == "QUICK STOP ACTIVE" and self.stopping):
            speed = self.demand_v
            slower = max(abs(speed) - self.stop_dec * dt, 0.0)
            self.demand_v = math.copysign(slower, speed) if slower else 0.0
            self._set_demand(self.demand + self.demand_v * dt)
            if self.demand_v == 0.0:
                self.stopping = ""
                if self.state == "FAULT REACTION ACTIVE":
                    self._enter("FAULT")  # 14
                elif self._get(0x605A) in (1, 2, 3, 4):
                    self._enter("SWITCH ON DISABLED")
            return
        if self.state != "OPERATION ENABLED":
            return
        if self.mode == 8:
            target = self._clamp(float(self._get(0x607A))) - self.offset
            self.demand_v = (target - self.demand) / dt
            self._set_demand(target)
        elif self.mode == 1:
            self._profile(dt)
        elif self.mode == 6 and self.homing in ("search", "back", "settle"):
            self._homing_step(dt)
        else:
            self.demand_v = 0.0

    def _profile(self, dt: float) -> None:
        """PP: a trapezoid towards the set-point (0x6081 speed, 0x6083/0x6084 ramps)."""
        goal = self.demand if self.halted or self.pp_target is None else self.pp_target
        rest = goal - self.demand
        v_max = float(self._get(0x6081))
        acc, dec = float(self._get(0x6083)), float(self._get(0x6084))
        want = math.copysign(min(v_max, math.sqrt(2.0 * dec * abs(rest))), rest) if rest else 0.0
        speed = self.demand_v
        step = (acc if abs(want) > abs(speed) else dec) * dt
        speed = min(max(want, speed - step), speed + step)
        if abs(rest) <= abs(speed) * dt or (rest == 0.0 and abs(speed) <= step):
            self.demand_v = 0.0
            self._set_demand(goal)
        else:
            self.demand_v = speed
            self._set_demand(self.demand + speed * dt)

    # -- PDOs ---------------------------------------------------------------------------------
    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        """After canopen's NMT slave took the command: PDOs set up on entering OPERATIONAL,
        a reset boots again."""
        with self.lock:
            if self.stopped:
                return
            if self.node.nmt.state == "OPERATIONAL":
                for pdo in (*_maps(self.node.rpdo), *_maps(self.node.tpdo)):
                    self._unsubscribe(pdo)
                    pdo.read()  # the configuration the master wrote, from this node's own objects
                self.last_tpdo.clear()
                self.sync_rpdo.clear()
                self._send_event_tpdos()
            elif self.node.nmt.state == "INITIALISING":  # reset node or communication
                self.node.nmt.state = "INITIALISING"
                self.node.nmt.state = "PRE-OPERATIONAL"

    def _unsubscribe(self, pdo: PdoMap) -> None:
        callbacks = self.network.subscribers.get(pdo.cob_id or -1, [])
        if pdo.on_message in callbacks:
            self.network.unsubscribe(pdo.cob_id, pdo.on_message)

    def _on_rpdo(self, pdo: PdoMap) -> None:
        with self.lock:
            if self.stopped or self.node.nmt.state != "OPERATIONAL":
                return
            if pdo.trans_type is not None and pdo.trans_type <= 240:
                if pdo not in self.sync_rpdo:
                    self.sync_rpdo.append(pdo)
            else:
                self._apply_rpdo(pdo)

    def _apply_rpdo(self, pdo: PdoMap) -> None:
        for var in pdo.map:
            if var.length:
                # a value the object refuses by PDO is dropped, as by SDO
                with contextlib.suppress(SdoAbortedError):
                    self.node.set_data(var.index, var.subindex, var.get_data())

    def _tpdos(self) -> list[tuple[PdoMap, int]]:
        """The enabled TPDOs and their transmission types."""
        return [(p, p.trans_type) for p in _maps(self.node.tpdo) if p.enabled and p.trans_type is not None]

    def _send_event_tpdos(self) -> None:
        if self.stopped or self.node.nmt.state != "OPERATIONAL":
            return
        for tpdo, kind in self._tpdos():
            if kind >= 254:
                self._send_tpdo(tpdo, always=False)

    def _send_tpdo(self, tpdo: PdoMap, always: bool) -> None:
        for var in tpdo.map:
            if var.length:
                var.set_data(self.node.get_data(var.index, var.subindex))
        data = bytes(tpdo.data)
        if always or self.last_tpdo.get(tpdo.cob_id or 0) != data:
            self.last_tpdo[tpdo.cob_id or 0] = data
            tpdo.transmit()


def _maps(pdos: PdoBase) -> list[PdoMap]:
    """The PDO maps of a node's RPDOs or TPDOs."""
    return list(pdos.map.values()) if pdos.map is not None else []
