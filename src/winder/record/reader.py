"""Reading winder recordings back, ROS-free: a bag directory (or its .mcap)
in, numpy arrays out.

A recording is what the sim node writes (:mod:`winder.record.bag`): a rosbag2
directory ``<job_id>_<UTC stamp>/`` with ``metadata.yaml`` and one MCAP file.
:func:`read_run` returns a :class:`Run`: the job plan, the motor set-up the
simulation used, the timed step rows, the commanded and simulated joint
samples and the sim node's final report.

Cut-short recordings
--------------------
When the sim node dies mid-job (SIGKILL, power loss) the directory holds an
MCAP file without its summary and footer, and no metadata.yaml; rosbags and
``ros2 bag`` refuse it. The file is read here record by record with the
``mcap`` library's record parsers: every record that reached the file whole is
kept, and reading stops cleanly at the first incomplete one. Inside the last,
incomplete chunk (rosbags writes uncompressed chunks of about 1 MiB by
default) the messages that are whole are recovered too. Such a run is
``recovered`` and never ``complete``; :func:`recover` writes it out again as a
closed rosbag2 directory.

Everything here is ROS-free: messages are decoded with the ``rosbags``
typestore of ROS 2 Jazzy.
"""

from __future__ import annotations

import io
import json
import math
import mmap
import re
import shutil
import struct
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
from mcap.data_stream import ReadDataStream
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema

from winder.contract.stream import TIMED_COLUMNS, JobPlan, parse_job_description
from winder.motion.job import AXES

__all__ = [
    "AxisConfig",
    "BagError",
    "RawBag",
    "Run",
    "Samples",
    "SimConfig",
    "read_raw",
    "read_run",
    "recover",
]

MAGIC = b"\x89MCAP0\r\n"
FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: the winder topics, relative to the cell's namespace
JOB, SIM_CONFIG, PATH, STEP_TIMES = "winder/job", "winder/sim_config", "winder/path", "winder/step_times"
JOINT_COMMANDS, JOINT_STATES = "winder/joint_commands", "winder/joint_states"
PROFILE_CONFIG = "winder/profile_config"
DIAGNOSTICS = "/diagnostics"


class BagError(ValueError):
    """A recording cannot be read; the message says which file and why, in one line."""


# -- raw MCAP -------------------------------------------------------------------


@dataclass(frozen=True)
class Connection:
    """One MCAP channel: topic, ROS type and the type's definition text."""

    id: int
    topic: str
    msgtype: str
    encoding: str  #: message encoding, "cdr" for ROS 2
    schema_encoding: str  #: "ros2msg" or "ros2idl"
    schema: str  #: message definition text


@dataclass
class RawBag:
    """The messages of a recording, undecoded, in file order.

    ``closed``: every file ended with its MCAP footer. ``recovered``: some file
    was cut short (or damaged) and was read up to its first incomplete record.
    """

    path: Path
    files: list[Path]
    connections: dict[int, Connection]
    messages: list[tuple[int, int, bytes]]  #: (connection id, log time ns, CDR bytes)
    closed: bool
    recovered: bool
    metadata: bool = False  #: metadata.yaml present
    notes: list[str] = field(default_factory=list)

    def topics(self) -> dict[str, int]:
        """Message count per topic."""
        counts = {c.topic: 0 for c in self.connections.values()}
        for cid, _, _ in self.messages:
            topic = self.connections[cid].topic
            counts[topic] = counts.get(topic, 0) + 1
        return counts


def _bag_files(path: Path) -> tuple[Path, list[Path], bool]:
    """(bag directory or file, the MCAP files to read, metadata.yaml present)."""
    if not path.exists():
        raise BagError(f"{path}: no such file or directory")
    if path.is_file():
        if path.name == "metadata.yaml":
            return _bag_files(path.parent)
        return path, [path], (path.parent / "metadata.yaml").exists()
    if not path.is_dir():
        raise BagError(f"{path}: not a directory or a regular file")
    meta = path / "metadata.yaml"
    files: list[Path] = []
    if meta.exists():
        text = meta.read_text(errors="replace")
        if re.search(r"storage_identifier:\s*sqlite3", text):
            db3 = sorted(path.glob("*.db3"))
            if not db3:
                raise BagError(f"{path}: metadata.yaml names an sqlite3 recording, but there is no .db3 file")
            return path, db3, True
        listed = re.findall(r"^\s*(?:-\s*)?path:\s*(\S+)", text, flags=re.M)
        files = [path / name for name in listed if (path / name).exists()]
    if not files:
        files = sorted(p for p in path.glob("*.mcap") if p.is_file())
    if not files:
        entries = [p.name for p in path.iterdir()]
        if not entries:
            raise BagError(f"{path}: empty directory, not a rosbag2 recording (no metadata.yaml, no .mcap)")
        if meta.exists():
            raise BagError(f"{path}: metadata.yaml lists no MCAP file that exists here")
        raise BagError(f"{path}: not a rosbag2 recording (no metadata.yaml and no .mcap file)")
    return path, files, meta.exists()


def _parse_chunk_partial(body: bytes | memoryview) -> tuple[str, bytes] | None:
    """Compression and the records of a chunk record cut short (its body up to
    the cut): as much of the chunk's record data as can be had, or None."""
    if len(body) < 8 + 8 + 8 + 4 + 4:
        return None
    clen = int.from_bytes(body[28:32], "little")
    start = 32 + clen + 8
    if len(body) < start:
        return None
    compression = bytes(body[32 : 32 + clen]).decode("utf-8", "replace")
    data = bytes(body[start:])
    if compression == "":
        return compression, data
    if compression == "zstd":
        try:
            import zstandard

            return compression, zstandard.ZstdDecompressor().decompressobj().decompress(data)
        except Exception:  # a cut inside a frame: nothing usable
            return None
    return None  # lz4 frames cannot be read before their end


_MSG_HEAD = struct.Struct("<HIQQ")  # channel id, sequence, log time, publish time


def _inner_records(data: bytes | memoryview) -> Iterator[Schema | Channel | tuple[int, int, bytes]]:
    """The whole records inside (part of) a chunk's record data, in order:
    Schema and Channel records (parsed by ``mcap``), messages as (channel id,
    log time, bytes). Stops at the first incomplete record."""
    pos, n = 0, len(data)
    while pos + 9 <= n:
        op = data[pos]
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        end = pos + 9 + length
        if end > n:
            return
        if op == Opcode.MESSAGE:
            cid, _, log_time, _ = _MSG_HEAD.unpack_from(data, pos + 9)
            yield cid, log_time, bytes(data[pos + 9 + _MSG_HEAD.size : end])
        elif op == Opcode.SCHEMA:
            yield Schema.read(ReadDataStream(io.BytesIO(data[pos + 9 : end])))
        elif op == Opcode.CHANNEL:
            yield Channel.read(ReadDataStream(io.BytesIO(data[pos + 9 : end])))
        pos = end


def _chunk_data(chunk: Chunk) -> bytes:
    if chunk.compression == "":
        return chunk.data
    if chunk.compression == "zstd":
        import zstandard

        return zstandard.ZstdDecompressor().decompress(chunk.data, max_output_size=chunk.uncompressed_size)
    if chunk.compression == "lz4":
        import lz4.frame

        return lz4.frame.decompress(chunk.data)  # type: ignore[no-any-return]
    raise ValueError(f"unsupported chunk compression {chunk.compression!r}")


def _read_mcap(path: Path, raw: RawBag) -> None:
    """Append the records of one MCAP file to ``raw``, stopping cleanly at the
    first incomplete or damaged record."""
    size = path.stat().st_size
    if size == 0:
        raise BagError(f"{path}: empty file (0 bytes)")
    with path.open("rb") as f, mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ) as mm:
        data = memoryview(mm)
        try:
            _scan(path, data, raw)
        finally:
            data.release()


def _scan(path: Path, data: memoryview, raw: RawBag) -> None:
    n = len(data)
    if bytes(data[:8]) != MAGIC:
        if bytes(data[:8]) == MAGIC[: min(8, n)] and n < 8:
            raise BagError(f"{path}: MCAP file cut short inside its header, damaged beyond recovery")
        raise BagError(f"{path}: not an MCAP file (it does not start with the MCAP magic bytes)")
    schemas: dict[int, Schema] = {}
    offset = max(raw.connections, default=0)  # ids of later split files follow on
    ids: dict[int, int] = {}
    footer = False
    pos = 8
    damaged = ""

    def add(rec: Schema | Channel | Message | tuple[int, int, bytes]) -> None:
        if isinstance(rec, tuple):
            if rec[0] in ids:
                raw.messages.append((ids[rec[0]], rec[1], rec[2]))
        elif isinstance(rec, Schema):
            schemas[rec.id] = rec
        elif isinstance(rec, Channel):
            if rec.id not in ids:
                sch = schemas.get(rec.schema_id)
                cid = offset + rec.id
                ids[rec.id] = cid
                raw.connections[cid] = Connection(
                    cid,
                    rec.topic,
                    sch.name if sch else "",
                    rec.message_encoding,
                    sch.encoding if sch else "",
                    bytes(sch.data).decode("utf-8", "replace") if sch else "",
                )
        elif rec.channel_id in ids:
            raw.messages.append((ids[rec.channel_id], rec.log_time, rec.data))

    while pos + 9 <= n:
        op = data[pos]
        length = int.from_bytes(data[pos + 1 : pos + 9], "little")
        end = pos + 9 + length
        if end > n:
            break
        body = data[pos + 9 : end]
        try:
            if op == Opcode.FOOTER:
                footer = True
                pos = end
                break
            if op == Opcode.CHUNK:
                chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
                for rec in _inner_records(_chunk_data(chunk)):
                    add(rec)
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
                stream = ReadDataStream(io.BytesIO(body))
                add(Schema.read(stream) if op == Opcode.SCHEMA else Channel.read(stream))
            elif op == Opcode.MESSAGE:
                add(Message.read(ReadDataStream(io.BytesIO(body)), length))
        except Exception as exc:  # a damaged record: keep what came before it
            damaged = f"damaged record at byte {pos} ({type(exc).__name__})"
            break
        pos = end
    if footer and bytes(data[pos : pos + 8]) == MAGIC:
        return
    raw.closed = False
    if footer:
        raw.recovered = True
        raw.notes.append(f"{path.name}: cut short inside its closing magic bytes; every message was read")
        return
    raw.recovered = True
    if damaged:
        raw.notes.append(f"{path.name}: {damaged}; {n - pos} bytes after it not read")
        return
    # the record the file was cut in: a chunk may still hold whole messages
    if pos + 9 <= n and data[pos] == Opcode.CHUNK:
        part = _parse_chunk_partial(data[pos + 9 :])
        if part is not None:
            try:
                for rec in _inner_records(part[1]):
                    add(rec)
            except Exception:
                pass
    where = f"inside the record at byte {pos}" if pos < n else "after a whole record"
    raw.notes.append(
        f"{path.name}: cut short at byte {n} ({where}), without summary and footer; "
        "every whole message before the cut was read"
    )


def _read_sqlite(path: Path, files: list[Path], raw: RawBag) -> None:
    from rosbags.rosbag2 import Reader

    try:
        with Reader(path) as reader:
            for c in reader.connections:
                raw.connections[c.id] = Connection(
                    c.id, c.topic, c.msgtype, "cdr", "ros2msg", c.msgdef.data if c.msgdef else ""
                )
            for conn, t, data in reader.messages():
                raw.messages.append((conn.id, t, bytes(data)))
    except Exception as exc:
        raise BagError(f"{path}: rosbag2 (sqlite3) recording cannot be read: {exc}") from None


def read_raw(path: str | Path) -> RawBag:
    """Every readable message of a recording (directory, metadata.yaml or .mcap file)."""
    bag, files, meta = _bag_files(Path(path))
    raw = RawBag(bag, files, {}, [], closed=True, recovered=False, metadata=meta)
    if files and files[0].suffix == ".db3":
        _read_sqlite(bag, files, raw)
        return raw
    for f in files:
        try:
            _read_mcap(f, raw)
        except OSError as exc:
            raise BagError(f"{f}: cannot be read: {exc.strerror or exc}") from None
    if raw.closed and bag.is_dir() and not meta:
        raw.notes.append("metadata.yaml missing (the MCAP file itself is complete)")
    if not raw.messages:
        if raw.recovered:
            raise BagError(
                f"{bag}: damaged beyond recovery: the MCAP file is cut short before its first whole message"
            )
        raise BagError(f"{bag}: empty recording: no messages")
    return raw


# -- decoding ---------------------------------------------------------------------


def _typestore() -> Any:
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


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
        return cls(str(doc["model"]), axes, float(doc["publish_rate"]), float(doc.get("settle_time", 0.0)))


@dataclass(frozen=True)
class Samples:
    """Joint samples: times ``t`` (s, simulated), ``pos`` and ``vel`` (n, 3) in
    joint units (feed m, fork rad, pole rad; per s), axes in AXES order."""

    t: FloatArray
    pos: FloatArray
    vel: FloatArray

    @classmethod
    def empty(cls) -> Samples:
        return cls(np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))

    def __len__(self) -> int:
        return int(self.t.size)


@dataclass(frozen=True)
class Run:
    """One recorded winding job, decoded (see module doc).

    ``steps``: (N, 5) int64 rows [t_ns since job start, segment, feed, fork,
    pole], positions after each step, as the stream arrived. ``report``: the
    sim node's last job status (key -> value text: state, steps_done,
    lost_steps, real_time_factor, ...), empty if none was recorded.
    ``complete``: the bag was closed and the sim node reported the job done.
    """

    path: Path
    namespace: str
    plan: JobPlan
    sim_config: SimConfig | None
    steps: IntArray
    commands: Samples
    states: Samples
    report: dict[str, str]
    profile: str  #: velocity profile kind ("" if the recording does not say)
    closed: bool
    recovered: bool
    counts: dict[str, int]
    notes: tuple[str, ...] = ()
    #: the profile node's ramp settings (winder/profile_config: profile, v_max, a_max,
    #: j_max, tau, v_start, dwell in steps of the major axis, s), empty in older bags
    profile_config: dict[str, Any] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        return self.closed and self.report.get("state") == "done"

    @property
    def job_id(self) -> str:
        return self.plan.job_id

    @property
    def label(self) -> str:
        """A short name for tables: the bag's name."""
        return self.path.name


def _namespaces(topics: set[str]) -> list[str]:
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
    off = 8  # stamp
    (flen,) = struct.unpack_from("<I", body, off)
    off = align(off + 4 + flen, 4)
    (count,) = struct.unpack_from("<I", body, off)
    off += 4
    names = []
    for _ in range(count):
        off = align(off, 4)
        (slen,) = struct.unpack_from("<I", body, off)
        names.append(bytes(body[off + 4 : off + 3 + slen]).decode("utf-8", "replace"))
        off += 4 + slen
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
            pos = block[:, p_off : p_off + 8 * k].copy().view("<f8")[:, order]
            vel = block[:, v_off : v_off + 8 * k].copy().view("<f8")[:, order]
            first = _typestore().deserialize_cdr(datas[0], "sensor_msgs/msg/JointState")
            if np.array_equal(np.asarray(first.position)[order], pos[0]) and np.array_equal(
                np.asarray(first.velocity)[order], vel[0]
            ):
                return Samples(sec + nsec * 1e-9, pos, vel)
    return _joint_samples_slow(datas, topic)


def _joint_samples_slow(datas: list[bytes], topic: str) -> Samples:
    store = _typestore()
    n = len(datas)
    t = np.empty(n)
    pos = np.empty((n, 3))
    vel = np.zeros((n, 3))
    order: list[int] | None = None
    names0: list[str] | None = None
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
    return Samples(t, pos, vel)


def read_run(path: str | Path, namespace: str | None = None) -> Run:
    """Read a winder recording (bag directory, its metadata.yaml or .mcap file).

    ``namespace`` picks the cell when the bag holds several (``/cell1``); by
    default the one cell whose ``winder/job`` topic has a message. Raises
    :class:`BagError` (a ValueError) with a one-line reason.
    """
    raw = read_raw(path)
    counts = raw.topics()
    with_job = {t for t, c in counts.items() if c > 0}
    spaces = _namespaces(with_job)
    if namespace is not None:
        ns = "/" + namespace.strip("/") if namespace.strip("/") else ""
        if ns not in spaces:
            have = ", ".join(s or "/" for s in spaces) or "none"
            raise BagError(
                f"{raw.path}: no winder job in namespace {ns or '/'} (namespaces with a job: {have})"
            )
    elif not spaces:
        raise BagError(f"{raw.path}: not a winder bag: no /winder/job topic")
    elif len(spaces) > 1:
        raise BagError(
            f"{raw.path}: the bag holds {len(spaces)} winder cells ({', '.join(s or '/' for s in spaces)}): "
            "choose one with --namespace"
        )
    else:
        ns = spaces[0]

    topic = {
        key: f"{ns}/{key}"
        for key in (JOB, SIM_CONFIG, PROFILE_CONFIG, STEP_TIMES, JOINT_COMMANDS, JOINT_STATES)
    }
    wanted = {*topic.values(), DIAGNOSTICS}
    joints = {topic[JOINT_COMMANDS], topic[JOINT_STATES]}
    store = _typestore()
    decoded: dict[str, list[Any]] = {t: [] for t in wanted}
    for cid, _, data in raw.messages:
        conn = raw.connections[cid]
        if conn.topic not in wanted:
            continue
        if conn.topic in joints:
            if conn.msgtype != "sensor_msgs/msg/JointState":
                raise BagError(
                    f"{raw.path}: {conn.topic} has type {conn.msgtype}, not sensor_msgs/msg/JointState"
                )
            decoded[conn.topic].append(data)
            continue
        try:
            decoded[conn.topic].append(store.deserialize_cdr(data, conn.msgtype))
        except Exception as exc:
            raise BagError(
                f"{raw.path}: a {conn.topic} message ({conn.msgtype}) cannot be decoded: {exc}"
            ) from None

    try:
        plan = parse_job_description(decoded[topic[JOB]][0].data)
    except (ValueError, KeyError, TypeError) as exc:
        raise BagError(f"{raw.path}: {topic[JOB]}: {exc}") from None
    notes = list(raw.notes)
    sim_config = None
    if decoded[topic[SIM_CONFIG]]:
        try:
            sim_config = SimConfig.from_json(decoded[topic[SIM_CONFIG]][0].data)
        except (ValueError, KeyError, TypeError) as exc:
            raise BagError(f"{raw.path}: {topic[SIM_CONFIG]} is not a sim configuration: {exc}") from None
    else:
        notes.append(f"no {topic[SIM_CONFIG]} message: motor parameters unknown")
    chunks = [_unpack_steps(m, topic[STEP_TIMES]) for m in decoded[topic[STEP_TIMES]]]
    steps = np.vstack(chunks) if chunks else np.zeros((0, 5), np.int64)

    profile_config: dict[str, Any] = {}
    if decoded[topic[PROFILE_CONFIG]]:
        try:
            profile_config = dict(json.loads(decoded[topic[PROFILE_CONFIG]][-1].data))
        except (ValueError, TypeError):
            notes.append(f"{topic[PROFILE_CONFIG]} is not JSON: ramp settings unknown")
    prefix = f"{ns.strip('/')}/" if ns else ""
    report: dict[str, str] = {}
    profile = ""
    for arr in decoded[DIAGNOSTICS]:
        for st in arr.status:
            values = {kv.key: kv.value for kv in st.values}
            if st.name == f"{prefix}sim_node: job" and "state" in values:
                report = values
            elif st.name == f"{prefix}profile_node: job" and "profile" in values:
                profile = values["profile"]  # older bags: only the profile node's status says
    profile = str(profile_config.get("profile", profile))
    return Run(
        path=raw.path,
        namespace=ns,
        plan=plan,
        sim_config=sim_config,
        steps=steps,
        commands=_joint_samples(decoded[topic[JOINT_COMMANDS]], topic[JOINT_COMMANDS]),
        states=_joint_samples(decoded[topic[JOINT_STATES]], topic[JOINT_STATES]),
        report=report,
        profile=profile,
        closed=raw.closed,
        recovered=raw.recovered,
        counts=counts,
        notes=tuple(notes),
        profile_config=profile_config,
    )


# -- repair -------------------------------------------------------------------------


def recover(path: str | Path, out: str | Path | None = None) -> tuple[Path, int]:
    """Write the readable messages of a cut-short recording as a new, closed
    rosbag2/MCAP directory (default ``<bag>_recovered`` beside it); return the
    directory and the number of messages saved. Never writes into an existing
    directory; a failed write leaves nothing behind."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_types_from_msg

    raw = read_raw(path)
    src = raw.path
    if out is None:
        base = src if src.is_dir() else src.with_suffix("")
        out = base.with_name(base.name + "_recovered")
    out = Path(out)
    if out.exists():
        raise BagError(f"{out}: already exists; remove it or choose another name")
    store = _typestore()
    writer = Writer(out, version=9, storage_plugin=StoragePlugin.MCAP)
    saved = 0
    try:
        writer.open()
        conns: dict[int, Any] = {}
        by_topic: dict[tuple[str, str], Any] = {}
        for c in raw.connections.values():
            if c.encoding != "cdr" or not c.msgtype:
                continue
            if c.msgtype not in store.fielddefs and c.schema and c.schema_encoding == "ros2msg":
                try:
                    store.register(get_types_from_msg(c.schema, c.msgtype))
                except Exception:
                    continue
            if c.msgtype not in store.fielddefs:
                continue
            key = (c.topic, c.msgtype)
            if key not in by_topic:
                by_topic[key] = writer.add_connection(c.topic, c.msgtype, typestore=store)
            conns[c.id] = by_topic[key]
        for cid, t, data in raw.messages:
            conn = conns.get(cid)
            if conn is not None:
                writer.write(conn, t, data)
                saved += 1
        writer.close()
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    return out, saved
