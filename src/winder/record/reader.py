"""Reading winder recordings back, ROS-free: a bag directory (or its .mcap)
in, numpy arrays out.

A recording is what the sim node writes (:mod:`winder.record.bag`): a rosbag2
directory ``<job_id>_<UTC stamp>/`` with ``metadata.yaml`` and one MCAP file.
:func:`read_run` returns a :class:`Run`: the job plan, the motor set-up the
simulation used, the timed step rows, the commanded and simulated joint
samples and the consumer's final report (the sim node's, or a hardware
driver's in its place: found by its role, whatever its node name).

The steps: :mod:`winder.record.raw` walks the file(s) into a :class:`RawBag`
of undecoded messages (cut-short and damaged recordings too, see there); here
the messages of the chosen cell are decoded, per topic family, and assembled
into the :class:`Run`. A run read from a cut-short recording is ``recovered``
and never ``complete``; :func:`recover` writes such a recording out again as
a closed rosbag2 directory.

Memory stays bounded however long the job: the first walk keeps only the few
messages that describe the run (job, configurations, diagnostics), a second
one decodes the joint samples (their number grows with the job's duration,
not its steps) and checks the step chunks, and the step rows themselves are
never held whole: :attr:`Run.step_rows` reads them again, one chunk at a time,
each time it is iterated (:mod:`winder.analysis` streams through them).

Everything here is ROS-free: messages are decoded with the ``rosbags``
typestore of ROS 2 Jazzy.
"""

from __future__ import annotations

import json
import math
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from winder.contract.cdr import joint_state_names
from winder.contract.events import ControlEvent, EventError
from winder.contract.states import JobState
from winder.contract.stream import TIMED_COLUMNS, JobPlan, description_text, parse_job_description
from winder.contract.topics import (
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_JOINT_COMMANDS,
    TOPIC_JOINT_STATES,
    TOPIC_PROFILE_CONFIG,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
    TOPIC_TENSION,
    has_role,
    in_namespace,
    status_node,
)
from winder.motion.axes import AXES
from winder.record.raw import BagError, RawBag, _typestore, bag_typestore, read_raw, recover
from winder.spec import shorten

__all__ = [
    "AxisConfig",
    "BagError",
    "RawBag",
    "Run",
    "Samples",
    "SimConfig",
    "StepArray",
    "StepRows",
    "StepSource",
    "TensionSamples",
    "read_raw",
    "read_run",
    "recover",
]

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: the winder topics, relative to the cell's namespace
JOB, SIM_CONFIG, STEP_TIMES = TOPIC_JOB, TOPIC_SIM_CONFIG, TOPIC_STEP_TIMES
JOINT_COMMANDS, JOINT_STATES = TOPIC_JOINT_COMMANDS, TOPIC_JOINT_STATES
PROFILE_CONFIG, DIAGNOSTICS = TOPIC_PROFILE_CONFIG, TOPIC_DIAGNOSTICS
CONTROL, STATE = TOPIC_CONTROL, TOPIC_STATE
TENSION = TOPIC_TENSION


# -- decoding ---------------------------------------------------------------------


@dataclass(frozen=True)
class AxisConfig:
    """The motor of one simulated axis as the sim node recorded it (SI)."""

    Zr: float
    L: float
    i_a: float
    J: float
    D: float
    motor_step_angle: float
    load_torque: float = 0.0

    @property
    def peak_torque(self) -> float:
        """T_m = Z_r*L*i_a**2/2 (N*m)."""
        return 0.5 * self.Zr * self.L * self.i_a**2

    @property
    def stiffness(self) -> float:
        """K = Z_r**2*L*i_a**2/2 (N*m/rad), the linear model's torque per rad of error."""
        return self.Zr * self.peak_torque

    @property
    def pitch_steps(self) -> float:
        """Commanded steps in one tooth pitch 2*pi/Z_r: the angle one slip loses."""
        return (2 * math.pi / self.Zr) / self.motor_step_angle


@dataclass(frozen=True)
class SimConfig:
    """The sim node's ``winder/sim_config``: model, motors, output rate."""

    model: str
    axes: dict[str, AxisConfig]
    publish_rate: float
    settle_time: float
    #: where the job starts on the cell's /clock (ns; its joint states are
    #: stamped on that clock): 0 for a cell's first job and in older bags
    clock_origin_ns: int = 0
    #: wall-clock time of the job's start (ns since the epoch; 0 if not recorded)
    wall_start_ns: int = 0
    #: a re-simulation (winder resim): the recording its steps come from and that run's id
    source_bag: str = ""
    source_run_id: str = ""

    @classmethod
    def from_json(cls, text: str) -> SimConfig:
        doc = json.loads(text)
        axes = {}
        for axis in AXES:
            a = doc["axes"][axis]
            axes[axis] = AxisConfig(
                **{k: float(a[k]) for k in ("Zr", "L", "i_a", "J", "D", "motor_step_angle")},
                load_torque=float(a.get("load_torque", 0.0)),
            )
        return cls(
            str(doc["model"]),
            axes,
            float(doc["publish_rate"]),
            float(doc.get("settle_time", 0.0)),
            int(doc.get("clock_origin_ns", 0)),
            int(doc.get("wall_start_ns", 0)),
            str(doc.get("source_bag", "")),
            str(doc.get("source_run_id", "")),
        )


@dataclass(frozen=True)
class Samples:
    """Joint samples: times ``t`` (s, simulated), ``pos`` and ``vel`` (n, 3) in
    joint units (feed m, fork rad, pole rad; per s), axes in AXES order;
    ``extra``: the positions of the other joints recorded with them (the
    wire's ``supply``, m paid out, and ``dancer``, m), by name."""

    t: FloatArray
    pos: FloatArray
    vel: FloatArray
    extra: dict[str, FloatArray] = field(default_factory=dict)

    @classmethod
    def empty(cls) -> Samples:
        return cls(np.zeros(0), np.zeros((0, len(AXES))), np.zeros((0, len(AXES))))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class TensionSamples:
    """The wire's tension as recorded: times ``t`` (s from the run's start)
    and ``tension`` (N); empty where the run recorded none. A simulated wire's
    is winder/tension, timed by its stamps (simulated time); a hardware run's
    is its load cell's (the topic its winder/sim_config names as
    ``load_cell_topic``, a ros2_control bridge's), timed by when each reading
    was recorded: its log time less the run's wall-clock start, as the bag's
    other messages are (the load cell stamps its readings on its own clock)."""

    t: FloatArray
    tension: FloatArray

    @classmethod
    def empty(cls) -> TensionSamples:
        return cls(np.zeros(0), np.zeros(0))

    def __len__(self) -> int:
        return int(self.t.size)


def _wrench_samples(datas: list[bytes], topic: str) -> TensionSamples:
    """Decode WrenchStamped payloads (stamp and force.x): all of one length
    (one frame id, as the sim node writes them) at once with numpy, the first
    checked against the rosbags decoder; others one by one."""
    if not datas:
        return TensionSamples.empty()
    store = _typestore()
    first = store.deserialize_cdr(datas[0], "geometry_msgs/msg/WrenchStamped")
    size = len(datas[0])
    if datas[0][1] == 1 and all(len(d) == size for d in datas):
        (n,) = struct.unpack_from("<I", datas[0], 12)  # the frame id's length, its bytes after it
        force = 4 + 12 + n
        force += -(force - 4) % 8
        block = np.frombuffer(b"".join(datas), dtype=np.uint8).reshape(len(datas), size)
        sec = block[:, 4:8].copy().view("<i4")[:, 0].astype(np.float64)
        nsec = block[:, 8:12].copy().view("<u4")[:, 0].astype(np.float64)
        fx = block[:, force : force + 8].copy().view("<f8")[:, 0]
        if fx[0] == first.wrench.force.x and sec[0] == first.header.stamp.sec:
            return TensionSamples(sec + nsec * 1e-9, fx)
    msgs = [store.deserialize_cdr(d, "geometry_msgs/msg/WrenchStamped") for d in datas]
    t = np.array([m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs])
    return TensionSamples(t, np.array([m.wrench.force.x for m in msgs]))


class StepSource(Protocol):
    """The timed step rows of a run: (k, 5) int64 arrays [t_ns since job start,
    segment, feed, fork, pole] (positions after each step), chunk by chunk in
    the order the stream arrived; iterable any number of times."""

    def __iter__(self) -> Iterator[IntArray]: ...

    def __len__(self) -> int: ...


_NO_ROWS = np.zeros((0, len(TIMED_COLUMNS)), np.int64)


def _stack(chunks: Iterator[IntArray]) -> IntArray:
    parts = list(chunks)
    return np.vstack(parts) if parts else _NO_ROWS.copy()


class StepRows:
    """The step rows of a recording, read from the bag again, one recorded
    chunk at a time, each time they are iterated."""

    def __init__(self, raw: RawBag, topic: str, msgtype: str, rows: int) -> None:
        self._raw, self._topic, self._msgtype, self._rows = raw, topic, msgtype, rows

    def __len__(self) -> int:
        return self._rows

    def __iter__(self) -> Iterator[IntArray]:
        store = _typestore()
        for batch in self._raw.stream([self._topic]):
            for _, _, data in batch:
                yield _unpack_steps(
                    _deserialize(store, self._raw.path, self._topic, data, self._msgtype), self._topic
                )


class StepArray:
    """Step rows held in memory, given out in chunks of ``chunk`` rows (for
    tests of the streamed analysis, and for runs built in memory)."""

    def __init__(self, rows: IntArray, chunk: int = 8192) -> None:
        if chunk < 1:
            raise ValueError(f"chunk={chunk} is invalid: must be >= 1")
        self._rows, self._chunk = np.asarray(rows, dtype=np.int64).reshape(-1, len(TIMED_COLUMNS)), chunk

    def __len__(self) -> int:
        return int(self._rows.shape[0])

    def __iter__(self) -> Iterator[IntArray]:
        for i in range(0, self._rows.shape[0], self._chunk):
            yield self._rows[i : i + self._chunk]


@dataclass(frozen=True)
class Run:
    """One recorded winding job, decoded (see module doc).

    ``step_rows``: the timed step rows (:class:`StepSource`), streamed;
    :attr:`steps` holds them all in one array (for small runs). ``report``: the
    consumer's last job status (key -> value text: state, steps_done,
    lost_steps, real_time_factor, ...), empty if none was recorded.
    ``complete``: the bag was closed, no chunk of it was damaged, and the
    consumer reported the job done. ``damaged``: the chunks skipped because their
    CRC or compression showed damage (their messages are not in the run).
    """

    path: Path
    namespace: str
    plan: JobPlan
    sim_config: SimConfig | None
    step_rows: StepSource
    commands: Samples
    states: Samples
    report: dict[str, str]
    profile: str  #: velocity profile kind ("" if the recording does not say)
    closed: bool
    recovered: bool
    counts: dict[str, int]
    notes: tuple[str, ...] = ()
    damaged: tuple[str, ...] = ()
    #: the ERROR statuses the cell's nodes published during the run, as
    #: recorded ("at <t> s: <node>: <task>: <message>", each different one
    #: once, t the simulated time it was recorded at)
    errors: tuple[str, ...] = ()
    #: the same ERROR statuses as recorded: each different one's first, its
    #: ``name``, ``message`` and values (key -> text)
    error_statuses: tuple[dict[str, str], ...] = ()
    #: the profile node's ramp settings (winder/profile_config: profile, v_max, a_max,
    #: j_max, tau, v_start, dwell in steps of the major axis, s), empty in older bags
    profile_config: dict[str, Any] = field(default_factory=dict)
    #: operator events (winder/control: pause, resume, abort, override), each a
    #: dict with ``event``, ``t_ns`` (simulated time since the job's start) and,
    #: for a stop, ``t_rest_ns``, ``steps``, ``stop_distance``; empty if none
    events: tuple[dict[str, Any], ...] = ()
    #: how the bag's MCAP chunks are compressed ("lz4", "zstd", "none"; several
    #: comma-separated if they differ; "" if it holds no chunks, e.g. sqlite3)
    compression: str = ""
    #: the wire's tension (winder/tension, or the load cell's of a hardware run), where recorded
    tension: TensionSamples = field(default_factory=TensionSamples.empty)

    @property
    def complete(self) -> bool:
        return self.closed and not self.damaged and self.report.get("state") == JobState.DONE

    @property
    def steps(self) -> IntArray:
        """All step rows as one (N, 5) array: memory grows with the job; the
        analysis iterates :attr:`step_rows` instead."""
        return _stack(iter(self.step_rows))

    @property
    def steps_recorded(self) -> int:
        return len(self.step_rows)

    @property
    def job_id(self) -> str:
        return self.plan.job_id

    @property
    def run_id(self) -> str:
        """The run's identity ("" in bags recorded before run ids)."""
        return self.plan.run_id

    @property
    def label(self) -> str:
        """A short name for tables: the bag's name."""
        return self.path.name


def job_namespaces(topics: set[str]) -> list[str]:
    """The namespaces of the cells whose ``winder/job`` is among ``topics``."""
    return sorted({t[: -len("/" + JOB)] for t in topics if t == "/" + JOB or t.endswith("/" + JOB)})


def _unpack_steps(msg: Any, topic: str) -> IntArray:
    dims = msg.layout.dim
    cols = len(TIMED_COLUMNS)
    if len(dims) != 2 or dims[1].size != cols or dims[1].label != ",".join(TIMED_COLUMNS):
        raise BagError(
            f"{topic}: chunk layout {[(d.label, d.size) for d in dims]} is not "
            f"(steps, {','.join(TIMED_COLUMNS)})"
        )
    data = np.asarray(msg.data, dtype=np.int64)
    if data.size != dims[0].size * cols:
        raise BagError(f"{topic}: chunk holds {data.size} values, layout says {dims[0].size} x {cols}")
    return data.reshape(dims[0].size, cols)


def _joint_layout(data: bytes) -> tuple[list[str], int, int] | None:
    """Joint names and the byte offsets of the position and velocity arrays of a
    little-endian CDR sensor_msgs/JointState, or None if it is not laid out as
    three positions and three velocities."""

    def align(off: int, n: int) -> int:
        return off + (-off % n)

    if len(data) < 16 or data[1] != 1:
        return None
    body = memoryview(data)[4:]
    names, off = joint_state_names(body)
    offsets = []
    for _ in range(2):  # position, velocity
        off = align(off, 4)
        (n,) = struct.unpack_from("<I", body, off)
        off += 4
        if n != len(names):
            return None
        off = align(off, 8)
        offsets.append(4 + off)
        off += 8 * n
    if 4 + off > len(data):
        return None
    return names, offsets[0], offsets[1]


def _joint_samples(datas: list[bytes], topic: str) -> Samples:
    """Decode JointState messages into arrays. Messages with one layout (same
    frame id and names, as the sim node writes them) are decoded together with
    numpy; the stamps, positions and velocities are checked against the rosbags
    decoder on the first message."""
    if not datas:
        return Samples.empty()
    n = len(datas)
    layout = _joint_layout(datas[0])
    L = len(datas[0])
    if layout is not None and all(len(d) == L for d in datas):
        names, p_off, v_off = layout
        block = np.frombuffer(b"".join(datas), dtype=np.uint8).reshape(n, L)
        if np.array_equal(block[:, 12:p_off], np.broadcast_to(block[0, 12:p_off], (n, p_off - 12))):
            try:
                order = [names.index(a) for a in AXES]
            except ValueError:
                raise BagError(f"{topic}: joint names {names} are not {', '.join(AXES)}") from None
            k = len(names)
            sec = block[:, 4:8].copy().view("<i4")[:, 0].astype(np.float64)
            nsec = block[:, 8:12].copy().view("<u4")[:, 0].astype(np.float64)
            every = block[:, p_off : p_off + 8 * k].copy().view("<f8")
            pos = every[:, order]
            vel = block[:, v_off : v_off + 8 * k].copy().view("<f8")[:, order]
            first = _typestore().deserialize_cdr(datas[0], "sensor_msgs/msg/JointState")
            if np.array_equal(np.asarray(first.position)[order], pos[0]) and np.array_equal(
                np.asarray(first.velocity)[order], vel[0]
            ):
                extra = {name: every[:, j].copy() for j, name in enumerate(names) if name not in AXES}
                return Samples(sec + nsec * 1e-9, pos, vel, extra)
    return _joint_samples_slow(datas, topic)


def _joint_samples_slow(datas: list[bytes], topic: str) -> Samples:
    store = _typestore()
    n = len(datas)
    t = np.empty(n)
    pos = np.empty((n, len(AXES)))
    vel = np.zeros((n, len(AXES)))
    order: list[int] | None = None
    names0: list[str] | None = None
    extra: dict[str, FloatArray] = {}
    for i, data in enumerate(datas):
        m = store.deserialize_cdr(data, "sensor_msgs/msg/JointState")
        names = list(m.name)
        if names != names0:
            try:
                order = [names.index(a) for a in AXES]
            except ValueError:
                raise BagError(f"{topic}: joint names {names} are not {', '.join(AXES)}") from None
            names0 = names
        assert order is not None
        t[i] = m.header.stamp.sec + m.header.stamp.nanosec * 1e-9
        p = np.asarray(m.position, dtype=np.float64)
        v = np.asarray(m.velocity, dtype=np.float64)
        if p.size != len(names):
            raise BagError(f"{topic}: a message has {p.size} positions for {len(names)} joints")
        pos[i] = p[order]
        if v.size == len(names):
            vel[i] = v[order]
        for j, name in enumerate(names):
            if name not in AXES:
                extra.setdefault(name, np.full(n, np.nan))[i] = p[j]
    return Samples(t, pos, vel, extra)


#: the topics whose messages the first walk keeps (they describe the run and
#: are few); step chunks and joint samples are streamed
#: DiagnosticStatus.ERROR
ERROR_LEVEL = 2
_KEPT = ("/" + JOB, "/" + SIM_CONFIG, "/" + PROFILE_CONFIG, "/" + CONTROL, "/" + STATE)
_JOINT_BATCH = 8192


def _kept(topic: str) -> bool:
    return topic == DIAGNOSTICS or topic.endswith(_KEPT)


def read_run(path: str | Path, namespace: str | None = None) -> Run:
    """Read a winder recording (bag directory, its metadata.yaml or .mcap file).

    ``namespace`` picks the cell when the bag holds several (``/cell1``); by
    default the one cell whose ``winder/job`` topic has a message. Raises
    :class:`BagError` (a ValueError) with a one-line reason.
    """
    raw = read_raw(path, keep=_kept)
    counts = raw.topics()
    ns = _pick_namespace(raw.path, counts, namespace)
    topic = {
        key: f"{ns}/{key}"
        for key in (
            JOB,
            SIM_CONFIG,
            PROFILE_CONFIG,
            CONTROL,
            STATE,
            STEP_TIMES,
            JOINT_COMMANDS,
            JOINT_STATES,
            TENSION,
        )
    }
    decoded = _decode(raw, topic)
    streamed = _stream_pass(raw, topic, _load_cell_topic(decoded[topic[SIM_CONFIG]]))
    return _assemble(raw, ns, counts, topic, decoded, streamed)


def _load_cell_topic(msgs: list[Any]) -> str:
    """The topic of the run's load cell, as its consumer's first configuration
    names it (``load_cell_topic``: a bridge's with a load cell); "" if none."""
    try:
        doc = json.loads(msgs[0].data) if msgs else {}
        name = doc.get("load_cell_topic", "") if isinstance(doc, dict) else ""
    except (ValueError, TypeError, AttributeError, RecursionError):
        return ""
    return name if isinstance(name, str) and name.startswith("/") else ""


def _pick_namespace(bag: Path, counts: dict[str, int], namespace: str | None) -> str:
    """The namespace of the cell to read: ``namespace`` if given, else the only
    one whose job topic has a message."""
    spaces = job_namespaces({t for t, c in counts.items() if c > 0})
    if namespace is not None:
        ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
        if ns not in spaces:
            have = ", ".join(s or "/" for s in spaces) or "none"
            raise BagError(
                f"{bag}: no winder job in namespace {(ns if len(ns) <= 52 else shorten(ns)) or '/'} "
                f"(namespaces with a job: {have})"
            )
        return ns
    if not spaces:
        raise BagError(f"{bag}: not a winder bag: no /winder/job topic")
    if len(spaces) > 1:
        raise BagError(
            f"{bag}: the bag holds {len(spaces)} winder cells ({', '.join(s or '/' for s in spaces)}): "
            "choose one with --namespace"
        )
    return spaces[0]


def _deserialize(store: Any, bag: Path, topic: str, data: bytes, msgtype: str) -> Any:
    try:
        return store.deserialize_cdr(data, msgtype)
    except Exception as exc:
        raise BagError(f"{bag}: a {topic} message ({msgtype}) cannot be decoded: {exc}") from None


def _decode(raw: RawBag, topic: dict[str, str]) -> dict[str, list[Any]]:
    """The kept messages of the cell's topics and of /diagnostics, per topic,
    in file order, decoded."""
    wanted = {*topic.values(), DIAGNOSTICS} - {topic[TENSION]}  # streamed (_stream_pass)
    store = bag_typestore(raw)  # the job description as this bag's winder wrote it
    decoded: dict[str, list[Any]] = {t: [] for t in wanted}
    decoded[_DIAGNOSTIC_TIMES] = []  # the log time of each /diagnostics message
    for cid, t, data in raw.messages:
        conn = raw.connections[cid]
        if conn.topic in wanted:
            decoded[conn.topic].append(_deserialize(store, raw.path, conn.topic, data, conn.msgtype))
            if conn.topic == DIAGNOSTICS:
                decoded[_DIAGNOSTIC_TIMES].append(t)
    return decoded


_DIAGNOSTIC_TIMES = " diagnostics log times"


@dataclass(frozen=True)
class _Streamed:
    commands: Samples
    states: Samples
    steps: StepSource
    tension: TensionSamples
    #: the log time (ns) of each tension sample: set where they are a load cell's (timed by it)
    tension_logged: IntArray | None = None
    notes: tuple[str, ...] = ()


_WRENCH_TYPE = "geometry_msgs/msg/WrenchStamped"


def _stream_pass(raw: RawBag, topic: dict[str, str], load_cell: str = "") -> _Streamed:
    """The second walk: the joint samples and the tension decoded (a batch at
    a time), the step chunks checked and counted but not kept. ``load_cell``:
    the topic of the run's load cell (its readings are the tension, with their
    log times), "" if none."""
    joints = (topic[JOINT_COMMANDS], topic[JOINT_STATES])
    steps_type = "std_msgs/msg/Int64MultiArray"
    wrench_topic = load_cell or topic[TENSION]
    notes = []
    for conn in raw.connections.values():
        if load_cell and conn.topic == load_cell and conn.msgtype != _WRENCH_TYPE:
            notes.append(f"{load_cell} (the load cell's topic) has type {conn.msgtype}: tension unknown")
            wrench_topic = ""
        if conn.topic in joints and conn.msgtype != "sensor_msgs/msg/JointState":
            raise BagError(
                f"{raw.path}: {conn.topic} has type {conn.msgtype}, not sensor_msgs/msg/JointState"
            )
        if conn.topic == topic[STEP_TIMES]:
            steps_type = conn.msgtype
    store = _typestore()
    pending: dict[str, list[bytes]] = {t: [] for t in joints}
    parts: dict[str, list[Samples]] = {t: [] for t in joints}
    wrenches: list[bytes] = []
    wrench_parts: list[TensionSamples] = []
    logged: list[int] = []
    rows = 0
    for batch in raw.stream({*joints, topic[STEP_TIMES], wrench_topic} - {""}):
        for name, t, data in batch:
            if name == wrench_topic:
                wrenches.append(data)
                logged.append(t)
                if len(wrenches) >= _JOINT_BATCH:
                    wrench_parts.append(_wrench_samples(wrenches, name))
                    wrenches = []
                continue
            if name == topic[STEP_TIMES]:
                msg = _deserialize(store, raw.path, name, data, steps_type)
                rows += _unpack_steps(msg, name).shape[0]
                continue
            pending[name].append(data)
            if len(pending[name]) >= _JOINT_BATCH:
                parts[name].append(_joint_samples(pending[name], name))
                pending[name] = []
    samples = {}
    for name in joints:
        if pending[name]:
            parts[name].append(_joint_samples(pending[name], name))
        samples[name] = _concat(parts[name])
    if wrenches:
        wrench_parts.append(_wrench_samples(wrenches, wrench_topic))
    tension = (
        TensionSamples(
            np.concatenate([p.t for p in wrench_parts]), np.concatenate([p.tension for p in wrench_parts])
        )
        if wrench_parts
        else TensionSamples.empty()
    )
    return _Streamed(
        samples[topic[JOINT_COMMANDS]],
        samples[topic[JOINT_STATES]],
        StepRows(raw, topic[STEP_TIMES], steps_type, rows),
        tension,
        np.array(logged, dtype=np.int64) if load_cell else None,
        tuple(notes),
    )


def _concat(parts: list[Samples]) -> Samples:
    if not parts:
        return Samples.empty()
    if len(parts) == 1:
        return parts[0]
    names = [name for name in parts[0].extra if all(name in p.extra for p in parts)]
    return Samples(
        np.concatenate([p.t for p in parts]),
        np.vstack([p.pos for p in parts]),
        np.vstack([p.vel for p in parts]),
        {name: np.concatenate([p.extra[name] for p in parts]) for name in names},
    )


def _assemble(
    raw: RawBag,
    ns: str,
    counts: dict[str, int],
    topic: dict[str, str],
    decoded: dict[str, list[Any]],
    streamed: _Streamed,
) -> Run:
    """The :class:`Run` of the cell in namespace ``ns`` from its decoded messages."""
    plan = _decode_plan(raw.path, decoded[topic[JOB]], topic[JOB])
    notes = [*raw.notes, *streamed.notes]
    sim_config = _decode_sim_config(raw.path, decoded[topic[SIM_CONFIG]], topic[SIM_CONFIG], notes)
    profile_config = _decode_profile_config(decoded[topic[PROFILE_CONFIG]], topic[PROFILE_CONFIG], notes)
    wall0, origin_ns = _time_base(decoded[topic[SIM_CONFIG]])
    # who announced the cell's state: a CellState names its node; an older bag
    # holds a DiagnosticStatus, named "<node>: state"
    consumer = {status_node(m.node if hasattr(m, "node") else m.name) for m in decoded[topic[STATE]]}
    report, profile, errors, error_statuses = _decode_diagnostics(
        decoded[DIAGNOSTICS], ns, decoded[_DIAGNOSTIC_TIMES], wall0, consumer
    )
    origin = origin_ns / 1e9
    return Run(
        path=raw.path,
        namespace=ns,
        plan=plan,
        sim_config=sim_config,
        step_rows=streamed.steps,
        commands=_shifted(streamed.commands, origin),
        states=_shifted(streamed.states, origin),
        report=report,
        profile=str(profile_config.get("profile", profile)),
        closed=raw.closed,
        recovered=raw.recovered,
        counts=counts,
        notes=tuple(notes),
        damaged=tuple(raw.damaged),
        errors=errors,
        error_statuses=error_statuses,
        profile_config=profile_config,
        events=_decode_events(decoded.get(topic[CONTROL], []), plan.run_id),
        compression=", ".join(sorted(raw.compressions)),
        tension=_tension(streamed, origin, wall0),
    )


def _tension(streamed: _Streamed, origin: float, wall0: int) -> TensionSamples:
    """The tension timed from the run's start: a simulated wire's by its stamps
    on the cell's clock (less the run's origin on it); a load cell's by when
    each reading was recorded (its log time less the run's wall-clock start,
    where the run's other messages, its joint states and commands, are
    timed from; the first reading's if the start is not recorded)."""
    logged = streamed.tension_logged
    if logged is None:
        return TensionSamples(streamed.tension.t - origin, streamed.tension.tension)
    if not logged.size:
        return TensionSamples.empty()
    base = wall0 if wall0 else int(logged[0])
    return TensionSamples((logged - base) / 1e9, streamed.tension.tension)


def _decode_events(msgs: list[Any], run_id: str) -> tuple[dict[str, Any], ...]:
    """The operator events of the run (winder/control), in the order recorded;
    messages that are not events of this run are left out."""
    out = []
    for m in msgs:
        # a winder_interfaces/ControlEvent (its JSON keys as before), or JSON in a std_msgs/String
        # (older bags: kept as recorded); either checked as the consumer checked it. What is
        # neither (another type on the topic) is no event.
        try:
            checked = ControlEvent.from_message(m)
            event = json.loads(m.data) if hasattr(m, "data") else json.loads(checked.to_wire())
        except (EventError, AttributeError, TypeError):
            continue
        if isinstance(event, dict) and event.get("run_id") == run_id and isinstance(event.get("t_ns"), int):
            out.append(event)
    return tuple(out)


def _shifted(samples: Samples, origin: float) -> Samples:
    """Samples stamped on the cell's clock, timed from their job's start."""
    if not origin:
        return samples
    return Samples(samples.t - origin, samples.pos, samples.vel, samples.extra)


def _decode_plan(bag: Path, msgs: list[Any], topic: str) -> JobPlan:
    """The job plan from the first job message."""
    try:
        return parse_job_description(description_text(msgs[0]))
    except (ValueError, KeyError, TypeError, AttributeError) as exc:  # AttributeError: another type
        raise BagError(f"{bag}: {topic}: {exc}") from None


def _decode_sim_config(bag: Path, msgs: list[Any], topic: str, notes: list[str]) -> SimConfig | None:
    """The sim node's configuration from its first message; None (and a note) if there is none."""
    if not msgs:
        notes.append(f"no {topic} message: motor parameters unknown")
        return None
    try:
        doc = json.loads(msgs[0].data)
    except (ValueError, TypeError, RecursionError) as exc:
        raise BagError(f"{bag}: {topic} is not JSON: {exc}") from None
    if isinstance(doc, dict) and "model" not in doc and "axes" not in doc:
        # a consumer that is no simulator (a hardware driver) configures its
        # run's time base and pacing only: no motor model to read
        notes.append(f"{topic} names no motor model (a hardware consumer): motor parameters unknown")
        return None
    try:
        return SimConfig.from_json(msgs[0].data)
    except (ValueError, KeyError, TypeError) as exc:
        raise BagError(f"{bag}: {topic} is not a sim configuration: {exc}") from None


def _time_base(msgs: list[Any]) -> tuple[int, int]:
    """(wall_start_ns, clock_origin_ns) of the run from the consumer's first
    configuration (any consumer's, simulator or not); zeros if unknown."""
    try:
        doc = json.loads(msgs[0].data) if msgs else {}
        wall0, origin = doc.get("wall_start_ns", 0), doc.get("clock_origin_ns", 0)
    except (ValueError, TypeError, AttributeError, RecursionError):
        return 0, 0
    ok = all(isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in (wall0, origin))
    return (wall0, origin) if ok else (0, 0)


def _decode_profile_config(msgs: list[Any], topic: str, notes: list[str]) -> dict[str, Any]:
    """The profile node's ramp settings from its last message; empty (with a
    note if the message is not JSON) if unknown."""
    if not msgs:
        return {}
    try:
        return dict(json.loads(msgs[-1].data))
    except (ValueError, TypeError):
        notes.append(f"{topic} is not JSON: ramp settings unknown")
        return {}


def _decode_diagnostics(
    msgs: list[Any], ns: str, times: list[int], wall0: int, consumer: set[str] | None = None
) -> tuple[dict[str, str], str, tuple[str, ...], tuple[dict[str, str], ...]]:
    """The consumer's last job status (the final report), the profile kind
    the profile node's status names (older bags say it only there) and the
    ERROR statuses of the cell in ``ns`` (each different one once, in order,
    with the simulated time it was first recorded at: the log time less the
    job's wall start), in words and as recorded (name, message, values).

    Nodes are found by their role (:func:`winder.contract.topics.has_role`),
    not their names: the consumer's status says ``role: consumer``; one
    recorded before roles existed is the consumer's if its node announced the
    cell's state (``consumer``: the node names on ``winder/state``, which the
    consumer publishes) or is named ``sim_node``."""
    nodes = consumer or set()
    report: dict[str, str] = {}
    profile = ""
    errors: dict[str, str] = {}
    statuses: dict[str, dict[str, str]] = {}
    for arr, t in zip(msgs, times, strict=True):
        for st in arr.status:
            values = {kv.key: kv.value for kv in st.values}
            if "state" in values and has_role(st.name, values, "consumer", ns, nodes):
                report = values
            elif "profile" in values and has_role(st.name, values, "profile", ns):
                profile = values["profile"]
            level = st.level if isinstance(st.level, int) else int.from_bytes(bytes(st.level), "little")
            text = f"{st.name}: {st.message}"
            if level == ERROR_LEVEL and in_namespace(st.name, ns) and text not in errors:
                at = f"at {(t - wall0) / 1e9:.3f} s: " if wall0 and t >= wall0 else ""
                errors[text] = at + text
                statuses[text] = {**values, "name": st.name, "message": st.message}
    return report, profile, tuple(errors.values()), tuple(statuses.values())
