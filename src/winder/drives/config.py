"""The drives file: the CAN bus, the SYNC period and one CiA 402 drive per
cell axis, every value checked before a bus is opened (ROS-free).

A drives file (YAML)::

    bus:                      # python-can's Bus(): interface, channel, bitrate, any other option
      interface: socketcan
      channel: can0
      bitrate: 500000
    sync_period: 0.004        # s: the SYNC period, also the drives' 0x60C2
    sdo_timeout: 0.3          # s: an SDO not answered within it is a fault (optional)
    axes:
      feed:                   # every axis of the cell (winder.motion.axes.AXIS_TABLE)
        node_id: 1
        eds: feed_drive.eds   # the vendor's EDS/DCF, relative to this file; "twin": winder's twin
        counts_per_unit: 2.0e6  # encoder counts per joint unit (m, or rad for a rotary axis)
        direction: 1          # -1: the drive counts the other way
        mode: 8               # 8 cyclic synchronous position; 1 profile position
        following_error: {window: 2000, time: 10}   # 0x6065 counts, 0x6066 ms
        limits: {min: -100000, max: 4000000}        # 0x607D counts (optional)
        quick_stop_option: 2  # 0x605A: 0, 1, 2, 5 or 6 (optional, 2)
        homing: {method: 35, offset: 0, speeds: {switch: 20000, zero: 2000},
                 acceleration: 100000, timeout: 30}  # optional: no homing
        heartbeat: {producer: 100, timeout: 500}    # ms: 0x1017, and how long the master waits
        position_window: 10   # 0x6067 counts (optional)
        profile: {velocity: 100000, acceleration: 1000000, deceleration: 1000000,
                  quick_stop_deceleration: 4000000}  # counts/s, counts/s^2 (optional)
    twin_fault: {axis: fork, at_sync: 500, fault: jam}  # virtual bus only (tests), optional

``twin_fault`` is a test's hook into the twins a node serves on a virtual
bus (:mod:`winder.ros.cia402_node`): at the ``at_sync``-th SYNC the twins
see, the axis' twin faults once: ``jam`` (the motor blocked: a following
error, by the twin's own monitoring), ``heartbeat`` (its heartbeat stops),
``sdo`` (its SDO server hangs until the master aborts a transfer:
:meth:`SimulatedDrive.hang_sdo`) or an EMCY error code (``0x2310``:
:meth:`SimulatedDrive.inject_fault`); or the bus fails: ``unplugged`` (the
master's python-can bus is shut down under it, as an adapter pulled out;
no ``axis``). A real bus has no twin to tell, so it is refused there.

A value that cannot be used is refused with one line naming the key, the
value and what it must be (:class:`DrivesFileError`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from winder.errors import BadInputError
from winder.motion.axes import AXES
from winder.spec import Spec

__all__ = [
    "BACKEND_SPECS",
    "AxisDrive",
    "BusConfig",
    "DrivesConfig",
    "DrivesFileError",
    "Homing",
    "TwinFault",
    "load_drives",
    "parse_drives",
    "period_object",
]

INT32 = (-(2**31), 2**31 - 1)
UINT32 = 2**32 - 1
UINT16 = 2**16 - 1
#: CAN bitrates (bit/s) a CANopen device may run at (CiA 301)
BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)
#: homing methods CiA 402 defines (0x6098)
HOMING_METHODS = (*range(1, 15), *range(17, 31), 33, 34, 35, 37)
QUICK_STOP_OPTIONS = (0, 1, 2, 5, 6)
MODES = {8: "cyclic synchronous position", 1: "profile position"}
SYNC_RANGE = (0.0005, 0.1)
#: the faults ``twin_fault`` can inject besides an EMCY code (see the module doc)
TWIN_FAULTS = ("jam", "heartbeat", "sdo", "unplugged")
#: the settings of a run on the drives (``Cia402Backend.specs``), here so that a node's
#: ``--help`` lists them without loading canopen
BACKEND_SPECS: dict[str, Spec] = {
    "real_time": Spec(
        "real_time", bool, True, "send SYNC at its period (false: as fast as the drives answer)"
    ),
    "require_homing": Spec("require_homing", bool, False, "home every axis before the run"),
}


class DrivesFileError(BadInputError):
    """A drives file, or a value in it, cannot be used: one line, the key, the value, the range."""


@dataclass(frozen=True)
class BusConfig:
    interface: str
    channel: str | int
    bitrate: int
    options: dict[str, Any] = field(default_factory=dict)

    def kwargs(self) -> dict[str, Any]:
        """python-can's Bus() arguments."""
        return {"interface": self.interface, "channel": self.channel, "bitrate": self.bitrate, **self.options}


@dataclass(frozen=True)
class Homing:
    method: int
    offset: int
    switch_speed: int
    zero_speed: int
    acceleration: int
    timeout: float


@dataclass(frozen=True)
class AxisDrive:
    """One axis' drive: everything the master writes to it, in counts."""

    axis: str
    node_id: int
    eds: str
    counts_per_unit: float
    direction: int
    mode: int
    following_window: int
    following_time: int
    quick_stop_option: int
    heartbeat_producer: int
    heartbeat_timeout: int
    limits: tuple[int, int] | None = None
    homing: Homing | None = None
    position_window: int | None = None
    profile: dict[int, int] = field(default_factory=dict)  # object index -> value (0x6081...)


@dataclass(frozen=True)
class TwinFault:
    """A fault one twin injects at a SYNC (a test's hook; see the module doc)."""

    axis: str  # "" for "unplugged"
    at_sync: int
    fault: str | int  # "jam", "heartbeat", "sdo", "unplugged", or an EMCY error code


@dataclass(frozen=True)
class DrivesConfig:
    source: str
    bus: BusConfig
    sync_period: float
    sdo_timeout: float
    axes: tuple[AxisDrive, ...]  # in the cell's axis order
    twin_fault: TwinFault | None = None


def period_object(period: float) -> tuple[int, int] | None:
    """0x60C2 (value, index) with value * 10**index == period s, value an
    unsigned byte; None if the period cannot be written so."""
    for index in range(-6, 0):
        value = period / 10.0**index
        if abs(value - round(value)) < 1e-6 * max(value, 1.0) and 1 <= round(value) <= 255:
            return round(value), index
    return None


class _Checker:
    """Reads one document, naming every refusal by its dotted key."""

    def __init__(self, source: str, base: Path | None) -> None:
        self.source = source
        self.base = base

    def fail(self, key: str, value: object, must: str) -> DrivesFileError:
        shown = repr(value)
        if len(shown) > 60:
            shown = shown[:57] + "..."
        return DrivesFileError(f"{self.source}: {key}={shown} is invalid: must be {must}")

    def table(
        self, key: str, value: object, allowed: tuple[str, ...], required: tuple[str, ...] = ()
    ) -> dict[str, Any]:
        if not isinstance(value, Mapping):
            raise self.fail(key, value, f"a mapping of {', '.join(allowed)}")
        for name in value:
            if name not in allowed:
                raise DrivesFileError(
                    f"{self.source}: {key}.{name} is not a setting: must be one of {', '.join(allowed)}"
                )
        for name in required:
            if name not in value:
                raise DrivesFileError(f"{self.source}: {key}.{name} is missing (required)")
        return dict(value)

    def integer(self, key: str, value: object, low: int, high: int, unit: str = "") -> int:
        if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
            raise self.fail(key, value, f"an integer in [{low}, {high}]" + (f" {unit}" if unit else ""))
        return value

    def number(
        self, key: str, value: object, low: float, high: float, unit: str, low_open: bool = False
    ) -> float:
        ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
        if ok:
            number = float(value)  # type: ignore[arg-type]
            ok = (low < number if low_open else low <= number) and number <= high
        if not ok:
            lo = "(" if low_open else "["
            raise self.fail(key, value, f"a number in {lo}{low:g}, {high:g}] {unit}")
        return float(value)  # type: ignore[arg-type]

    def choice(self, key: str, value: object, choices: tuple[int, ...], words: str = "") -> int:
        if isinstance(value, bool) or not isinstance(value, int) or value not in choices:
            raise self.fail(key, value, words or "one of " + ", ".join(str(c) for c in choices))
        return value

    def eds(self, key: str, value: object) -> str:
        if not isinstance(value, str) or not value:
            raise self.fail(key, value, 'the path of an EDS/DCF file, or "twin"')
        if value == "twin":
            from winder.drives.twin import EDS_PATH

            return EDS_PATH
        path = Path(value)
        if not path.is_absolute() and self.base is not None:
            path = self.base / path
        if not path.is_file():
            raise self.fail(key, value, f"an EDS/DCF file that exists (no file {path})")
        return str(path)


def _bus(c: _Checker, value: object) -> BusConfig:
    import can

    table = c.table("bus", value, ("interface", "channel", "bitrate", *_BUS_EXTRA), ("interface", "channel"))
    interface = table.pop("interface")
    if interface not in can.interfaces.VALID_INTERFACES:
        known = ", ".join(sorted(can.interfaces.VALID_INTERFACES))
        raise c.fail("bus.interface", interface, f"one of python-can's interfaces ({known})")
    channel = table.pop("channel")
    if isinstance(channel, bool) or not isinstance(channel, str | int) or channel == "":
        raise c.fail("bus.channel", channel, "a channel name or number (can0, PCAN_USBBUS1, 0)")
    bitrate = c.choice(
        "bus.bitrate",
        table.pop("bitrate", 500_000),
        BITRATES,
        "one of " + ", ".join(str(b) for b in BITRATES),
    )
    for name, option in table.items():
        if not isinstance(option, str | int | float | bool):
            raise c.fail(f"bus.{name}", option, "a string, number or true/false (a python-can option)")
    return BusConfig(str(interface), channel, bitrate, table)


#: python-can Bus() options a drives file may pass on (besides interface, channel, bitrate)
_BUS_EXTRA = (
    "receive_own_messages",
    "fd",
    "data_bitrate",
    "serial",
    "app_name",
    "tty_baudrate",
    "sleep_after_open",
    "rtscts",
    "timing",
    "local_loopback",
    "ignore_rx_error_frames",
    "preserve_timestamps",
    "poll_interval",
    "accept_virtual",
    "device_id",
    "sjw",
    "tseg1",
    "tseg2",
    "can_filters",
)


def _axis(c: _Checker, name: str, value: object) -> AxisDrive:
    k = f"axes.{name}"
    t = c.table(
        k,
        value,
        (
            "node_id",
            "eds",
            "counts_per_unit",
            "direction",
            "mode",
            "following_error",
            "limits",
            "quick_stop_option",
            "homing",
            "heartbeat",
            "position_window",
            "profile",
        ),
        ("node_id", "eds", "counts_per_unit", "mode", "following_error"),
    )
    node_id = c.integer(f"{k}.node_id", t["node_id"], 1, 127)
    eds = c.eds(f"{k}.eds", t["eds"])
    cpu = c.number(f"{k}.counts_per_unit", t["counts_per_unit"], 0.0, 1e12, "counts per joint unit", True)
    direction = c.choice(f"{k}.direction", t.get("direction", 1), (1, -1), "1 or -1")
    mode = c.choice(
        f"{k}.mode", t["mode"], tuple(MODES), "8 (cyclic synchronous position) or 1 (profile position)"
    )
    fe = c.table(f"{k}.following_error", t["following_error"], ("window", "time"), ("window", "time"))
    window = c.integer(f"{k}.following_error.window", fe["window"], 0, UINT32, "counts")
    fe_time = c.integer(f"{k}.following_error.time", fe["time"], 0, UINT16, "ms")
    limits = None
    if "limits" in t:
        lt = c.table(f"{k}.limits", t["limits"], ("min", "max"), ("min", "max"))
        low = c.integer(f"{k}.limits.min", lt["min"], *INT32, "counts")
        high = c.integer(f"{k}.limits.max", lt["max"], *INT32, "counts")
        if low >= high:
            raise c.fail(f"{k}.limits.max", high, f"above limits.min ({low})")
        limits = (low, high)
    qso = c.choice(f"{k}.quick_stop_option", t.get("quick_stop_option", 2), QUICK_STOP_OPTIONS)
    homing = None
    if "homing" in t:
        hk = f"{k}.homing"
        ht = c.table(hk, t["homing"], ("method", "offset", "speeds", "acceleration", "timeout"), ("method",))
        method = c.choice(
            f"{hk}.method", ht["method"], HOMING_METHODS, "a CiA 402 homing method (1-14, 17-30, 33-35, 37)"
        )
        offset = c.integer(f"{hk}.offset", ht.get("offset", 0), *INT32, "counts")
        st = c.table(f"{hk}.speeds", ht.get("speeds", {}), ("switch", "zero"))
        switch = c.integer(f"{hk}.speeds.switch", st.get("switch", 10_000), 1, UINT32, "counts/s")
        zero = c.integer(f"{hk}.speeds.zero", st.get("zero", 1_000), 1, UINT32, "counts/s")
        acc = c.integer(f"{hk}.acceleration", ht.get("acceleration", 100_000), 1, UINT32, "counts/s^2")
        timeout = c.number(f"{hk}.timeout", ht.get("timeout", 30.0), 0.0, 600.0, "s", True)
        homing = Homing(method, offset, switch, zero, acc, timeout)
    hb = c.table(f"{k}.heartbeat", t.get("heartbeat", {}), ("producer", "timeout"))
    producer = c.integer(f"{k}.heartbeat.producer", hb.get("producer", 100), 0, UINT16, "ms (0: none)")
    hb_timeout = c.integer(f"{k}.heartbeat.timeout", hb.get("timeout", 5 * producer), 0, UINT16, "ms")
    if producer and hb_timeout <= producer:
        raise c.fail(f"{k}.heartbeat.timeout", hb_timeout, f"longer than heartbeat.producer ({producer} ms)")
    pos_window = None
    if "position_window" in t:
        pos_window = c.integer(f"{k}.position_window", t["position_window"], 0, UINT32, "counts")
    profile: dict[int, int] = {}
    if "profile" in t:
        names = {
            "velocity": 0x6081,
            "acceleration": 0x6083,
            "deceleration": 0x6084,
            "quick_stop_deceleration": 0x6085,
        }
        pt = c.table(f"{k}.profile", t["profile"], tuple(names))
        for key, index in names.items():
            if key in pt:
                profile[index] = c.integer(f"{k}.profile.{key}", pt[key], 1, UINT32, "counts/s or counts/s^2")
    return AxisDrive(
        name, node_id, eds, cpu, direction, mode, window, fe_time, qso, producer, hb_timeout,
        limits, homing, pos_window, profile,
    )  # fmt: skip


def parse_drives(doc: object, source: str = "drives file", base: Path | None = None) -> DrivesConfig:
    """The drives configuration of a parsed document (see the module doc);
    ``base``: the directory relative EDS paths are in."""
    c = _Checker(source, base)
    top = c.table(
        "drives file",
        doc,
        ("bus", "sync_period", "sdo_timeout", "axes", "twin_fault"),
        ("bus", "sync_period", "axes"),
    )
    bus = _bus(c, top["bus"])
    period = c.number("sync_period", top["sync_period"], *SYNC_RANGE, "s")
    if period_object(period) is None:
        raise c.fail("sync_period", top["sync_period"], "a period 0x60C2 can hold (n * 10^k s, n in 1-255)")
    sdo_timeout = c.number("sdo_timeout", top.get("sdo_timeout", 0.3), 0.0, 10.0, "s", True)
    axes_doc = c.table("axes", top["axes"], AXES, AXES)
    axes = tuple(_axis(c, name, axes_doc[name]) for name in AXES)
    seen: dict[int, str] = {}
    for drive in axes:
        if drive.node_id in seen:
            raise c.fail(
                f"axes.{drive.axis}.node_id", drive.node_id, f"unique (axes.{seen[drive.node_id]} has it too)"
            )
        seen[drive.node_id] = drive.axis
    for drive in axes:
        _check_eds(c, drive)
    twin_fault = _twin_fault(c, top["twin_fault"], bus) if "twin_fault" in top else None
    return DrivesConfig(source, bus, period, sdo_timeout, axes, twin_fault)


def _twin_fault(c: _Checker, value: object, bus: BusConfig) -> TwinFault:
    if bus.interface != "virtual":
        raise c.fail("twin_fault", value, "absent unless bus.interface is virtual (the twins' bus)")
    t = c.table("twin_fault", value, ("axis", "at_sync", "fault"), ("at_sync", "fault"))
    if t["fault"] == "unplugged":  # the master's bus, no twin's
        if "axis" in t:
            raise c.fail("twin_fault.axis", t["axis"], "absent for fault unplugged (the bus fails, no twin)")
        t["axis"] = ""
    elif "axis" not in t:
        raise DrivesFileError(f"{c.source}: twin_fault.axis is missing (required)")
    elif t["axis"] not in AXES:
        raise c.fail("twin_fault.axis", t["axis"], f"one of {', '.join(AXES)}")
    at_sync = c.integer("twin_fault.at_sync", t["at_sync"], 1, 2**31 - 1)
    fault = t["fault"]
    ok = fault in TWIN_FAULTS or (
        isinstance(fault, int) and not isinstance(fault, bool) and 0x1000 <= fault <= 0xFFFF
    )
    if not ok:
        raise c.fail(
            "twin_fault.fault", fault, f"{', '.join(TWIN_FAULTS)} or an EMCY error code (0x1000-0xFFFF)"
        )
    return TwinFault(str(t["axis"]), at_sync, fault)


def _check_eds(c: _Checker, drive: AxisDrive) -> None:
    """The drive's EDS has every object the master will use (read without a bus)."""
    import canopen

    key = f"axes.{drive.axis}.eds"
    try:
        od = canopen.import_od(drive.eds, drive.node_id)
    except Exception as exc:
        why = " ".join(str(exc).split())[:80] or type(exc).__name__
        raise DrivesFileError(
            f"{c.source}: {key}={drive.eds!r} is invalid: must be an EDS/DCF file canopen can read ({why})"
        ) from None
    need = [0x1017, 0x1400, 0x1600, 0x1800, 0x1801, 0x1A00, 0x1A01, 0x603F, 0x6040, 0x6041, 0x6060,
            0x6061, 0x6064, 0x6065, 0x6066, 0x605A, 0x607A, 0x60F4, 0x6502]  # fmt: skip
    if drive.mode == 8:
        need.append(0x60C2)
    if drive.limits is not None:
        need.append(0x607D)
    if drive.homing is not None:
        need += [0x6098, 0x6099, 0x607C, 0x609A]
    if drive.position_window is not None:
        need.append(0x6067)
    need += list(drive.profile)
    missing = [f"0x{i:04X}" for i in need if i not in od]
    if missing:
        raise DrivesFileError(
            f"{c.source}: {key}={drive.eds!r} is invalid: must be the EDS of a CiA 402 drive with the "
            f"objects used (it lacks {', '.join(missing)})"
        )


def load_drives(path: str | Path) -> DrivesConfig:
    """Read and check a drives file (see the module doc): :class:`DrivesFileError` if it cannot be used."""
    from ruamel.yaml import YAML
    from ruamel.yaml.error import YAMLError

    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise DrivesFileError(f"{path}: cannot be read: {str(exc).splitlines()[0]}") from None
    try:
        doc = YAML(typ="safe").load(text)
    except YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise DrivesFileError(f"{path}: not YAML{where}: {problem}") from None
    return parse_drives(doc, str(path), path.parent)
