"""CDR (XCDR1, little endian) encoding of the sim node's high-rate messages,
ROS-free and vectorised: a block of samples becomes a block of payloads with
one numpy fill, instead of building and serializing a message object per
sample. The bytes are exact (no trailing alignment padding), so they are
published as they are (``Publisher.publish(bytes)``) and recorded unchanged.

Layouts (offsets from the start of the body, after the 4-byte encapsulation
header; primitives aligned to their size):

* ``rosgraph_msgs/Clock``: int32 sec, uint32 nanosec.
* ``sensor_msgs/JointState``: header (int32 sec, uint32 nanosec, string
  frame_id), string[] name, float64[] position, float64[] velocity,
  float64[] effort (empty).
* ``std_msgs/Int32MultiArray`` / ``Int64MultiArray`` (the step stream): layout
  (MultiArrayDimension[] dim: string label, uint32 size, uint32 stride; uint32
  data_offset), then int32[] / int64[] data. :class:`MultiArrayCodec` writes
  and reads the 2-D chunks of the topic contract without message objects: one
  copy of the rows out, none in (the rows are a view of the payload).
"""

from __future__ import annotations

import functools
import struct
from collections.abc import Sequence
from typing import Generic, TypeVar

import numpy as np
import numpy.typing as npt

from winder.errors import BadInputError

__all__ = [
    "CommandPayload",
    "JointStateEncoder",
    "JointStateReader",
    "MultiArrayCodec",
    "WrenchEncoder",
    "clock_payload",
    "encode_clocks",
    "joint_state_names",
    "trajectory_payload",
]

_HEADER = b"\x00\x01\x00\x00"  # CDR little endian, no options


def _split_ns(t_ns: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int32], npt.NDArray[np.uint32]]:
    sec, nsec = np.divmod(np.asarray(t_ns, dtype=np.int64), 1_000_000_000)
    return sec.astype(np.int32), nsec.astype(np.uint32)


def encode_clocks(t_ns: npt.ArrayLike) -> list[bytes]:
    """``rosgraph_msgs/Clock`` payloads for each time (ns)."""
    sec, nsec = _split_ns(np.asarray(t_ns))
    block = np.empty((sec.size, 12), dtype=np.uint8)
    block[:, :4] = np.frombuffer(_HEADER, np.uint8)
    block[:, 4:8] = sec.view(np.uint8).reshape(-1, 4)
    block[:, 8:12] = nsec.view(np.uint8).reshape(-1, 4)
    return [row.tobytes() for row in block]


class _Writer:
    """Builds a template body, remembering where the variable fields go."""

    def __init__(self) -> None:
        self.buf = bytearray()
        self.spans: list[tuple[int, int]] = []  #: (start, end) of every field written, padding excluded

    def align(self, n: int) -> None:
        self.buf += b"\x00" * (-len(self.buf) % n)

    def u32(self, v: int) -> int:
        self.align(4)
        at = len(self.buf)
        self.buf += struct.pack("<I", v)
        self.spans.append((at, at + 4))
        return at

    def string(self, s: str) -> None:
        data = s.encode() + b"\x00"
        self.u32(len(data))
        self.spans.append((len(self.buf), len(self.buf) + len(data)))
        self.buf += data

    def doubles(self, n: int) -> int:
        self.u32(n)
        if n:
            self.align(8)
        at = len(self.buf)
        self.buf += b"\x00" * (8 * n)
        return at


class JointStateEncoder:
    """``sensor_msgs/JointState`` payloads with fixed joint names and frame id:
    stamp, positions and velocities vary per sample, effort is empty."""

    def __init__(self, names: Sequence[str], frame_id: str) -> None:
        w = _Writer()
        self._stamp = w.u32(0)
        w.u32(0)  # nanosec
        w.string(frame_id)
        w.u32(len(names))
        for n in names:
            w.string(n)
        self.n = len(names)
        self._pos = w.doubles(self.n)
        self._vel = w.doubles(self.n)
        w.u32(0)  # effort: empty, and nothing after it
        self._template = np.frombuffer(_HEADER + bytes(w.buf), dtype=np.uint8)

    def encode(self, t_ns: npt.ArrayLike, position: npt.ArrayLike, velocity: npt.ArrayLike) -> list[bytes]:
        """One payload per row: ``position`` and ``velocity`` are (m, n)."""
        pos = np.ascontiguousarray(position, dtype="<f8")
        vel = np.ascontiguousarray(velocity, dtype="<f8")
        sec, nsec = _split_ns(np.asarray(t_ns))
        m = sec.size
        if pos.shape != (m, self.n) or vel.shape != (m, self.n):
            raise ValueError(f"position {pos.shape} and velocity {vel.shape} must be ({m}, {self.n})")
        block = np.tile(self._template, (m, 1))
        o = 4 + self._stamp
        block[:, o : o + 4] = sec.view(np.uint8).reshape(m, 4)
        block[:, o + 4 : o + 8] = nsec.view(np.uint8).reshape(m, 4)
        o = 4 + self._pos
        block[:, o : o + 8 * self.n] = pos.view(np.uint8).reshape(m, 8 * self.n)
        o = 4 + self._vel
        block[:, o : o + 8 * self.n] = vel.view(np.uint8).reshape(m, 8 * self.n)
        return [row.tobytes() for row in block]


class WrenchEncoder:
    """``geometry_msgs/WrenchStamped`` payloads with a fixed frame id: the
    stamp and ``force.x`` vary per sample (a load cell's reading along the
    wire, as ros2_control's force-torque broadcaster publishes it), the rest
    is 0."""

    def __init__(self, frame_id: str) -> None:
        w = _Writer()
        self._stamp = w.u32(0)
        w.u32(0)  # nanosec
        w.string(frame_id)
        w.align(8)
        self._force = len(w.buf)
        w.buf += b"\x00" * 48  # force x, y, z; torque x, y, z
        self._template = np.frombuffer(_HEADER + bytes(w.buf), dtype=np.uint8)

    def encode(self, t_ns: npt.ArrayLike, force_x: npt.ArrayLike) -> list[bytes]:
        """One payload per time: stamped ``t_ns``, ``force.x`` = ``force_x`` (N)."""
        sec, nsec = _split_ns(np.asarray(t_ns))
        fx = np.ascontiguousarray(force_x, dtype="<f8").reshape(-1)
        m = sec.size
        block = np.tile(self._template, (m, 1))
        o = 4 + self._stamp
        block[:, o : o + 4] = sec.view(np.uint8).reshape(m, 4)
        block[:, o + 4 : o + 8] = nsec.view(np.uint8).reshape(m, 4)
        o = 4 + self._force
        block[:, o : o + 8] = fx.view(np.uint8).reshape(m, 8)
        return [row.tobytes() for row in block]


def trajectory_payload(
    stamp_ns: int, frame_id: str, names: Sequence[str], offsets_ns: npt.ArrayLike, positions: npt.ArrayLike
) -> bytes:
    """A ``trajectory_msgs/JointTrajectory`` payload: header (``stamp_ns``,
    ``frame_id``), the joint ``names``, and one point per row of
    ``positions`` (m, n) at ``offsets_ns`` after the stamp (positions only:
    velocities, accelerations and effort empty). Exact bytes, as
    :class:`JointStateEncoder`'s (rclpy's serializer leaves bytes past the
    message's end, which rosbag readers refuse). A point that starts 4 bytes
    past a multiple of 8 needs no padding and ends so again: every point
    but perhaps the first is one fixed record, written for all at once."""
    pos = np.ascontiguousarray(positions, dtype="<f8")
    dt = np.asarray(offsets_ns, dtype=np.int64)
    n = len(names)
    if pos.ndim != 2 or pos.shape != (dt.size, n):
        raise ValueError(f"positions {pos.shape} must be ({dt.size}, {n})")
    w = _Writer()
    sec, nsec = divmod(int(stamp_ns), 1_000_000_000)
    w.buf += struct.pack("<iI", sec, nsec)
    w.string(frame_id)
    w.u32(n)
    for name in names:
        w.string(name)
    w.u32(dt.size)
    first = 0
    if dt.size and len(w.buf) % 8 != 4:  # the first point's positions are padded to 8
        at = w.doubles(n)
        w.buf[at : at + 8 * n] = pos[0].tobytes()
        w.u32(0), w.u32(0), w.u32(0)  # velocities, accelerations, effort: empty
        w.buf += struct.pack("<iI", *divmod(int(dt[0]), 1_000_000_000))
        first = 1
    block = np.zeros(dt.size - first, dtype=_point_record(n))
    block["n"] = n
    block["pos"] = pos[first:]
    block["sec"], block["nsec"] = np.divmod(dt[first:], 1_000_000_000)
    return _HEADER + bytes(w.buf) + block.tobytes()


@functools.cache
def _point_record(n: int) -> np.dtype[np.void]:
    """A JointTrajectoryPoint of ``n`` positions (and nothing else) that
    starts 4 bytes past a multiple of 8, as one fixed record."""
    return np.dtype(
        [("n", "<u4"), ("pos", "<f8", (n,)), ("empty", "<u4", (3,)), ("sec", "<i4"), ("nsec", "<u4")],
        align=False,
    )


IntT = TypeVar("IntT", np.int32, np.int64)


class MultiArrayCodec(Generic[IntT]):
    """2-D chunks of ``std_msgs/Int32MultiArray`` (``dtype`` int32) or
    ``Int64MultiArray`` (int64): dim 0 labelled ``rows_label``, dim 1 labelled
    with the comma-joined ``columns``, ``data_offset`` 0, row-major data."""

    def __init__(self, columns: Sequence[str], dtype: type[IntT], rows_label: str = "steps") -> None:
        self.columns = tuple(columns)
        self.cols = len(self.columns)
        self.dtype: np.dtype[IntT] = np.dtype(dtype).newbyteorder("<")
        if self.dtype.kind != "i" or self.dtype.itemsize not in (4, 8):
            raise ValueError(f"dtype={dtype!r} is invalid: must be int32 or int64")
        self.label = ",".join(self.columns)
        # body up to dim[0].size: count 2, label of dim 0
        w = _Writer()
        w.u32(2)
        w.string(rows_label)
        self._size0 = w.u32(0)
        w.u32(0)  # stride of dim 0
        w.string(self.label)
        w.u32(self.cols)
        w.u32(self.cols)
        w.u32(0)  # data_offset
        self._count = w.u32(0)
        w.align(self.dtype.itemsize)
        self._expect = _HEADER + bytes(w.buf)  # the header, sizes aside
        # the bytes a decoded header must match: all but the sizes and the
        # alignment padding (a serializer may leave padding uninitialised)
        sizes = (self._size0, self._size0 + 4, self._count)
        self._fixed = [(0, 2)] + [(a + 4, b + 4) for a, b in w.spans if a not in sizes]

    def encode(self, rows: npt.ArrayLike) -> bytes:
        """The payload of an (n, columns) array of rows."""
        a = np.ascontiguousarray(rows, dtype=self.dtype)
        if a.ndim != 2 or a.shape[1] != self.cols:
            raise ValueError(f"rows of shape {a.shape} must be (n, {self.cols})")
        n = a.shape[0]
        head = bytearray(self._expect)
        struct.pack_into("<II", head, 4 + self._size0, n, n * self.cols)
        struct.pack_into("<I", head, 4 + self._count, n * self.cols)
        return b"".join((head, a.data))

    def decode(self, raw: bytes) -> npt.NDArray[IntT]:
        """The (n, columns) rows of a payload, a read-only view of it; ValueError
        if the payload is not such a chunk (other layout, truncated)."""
        h = len(self._expect)
        if len(raw) < h or any(raw[a:b] != self._expect[a:b] for a, b in self._fixed):
            raise BadInputError(f"chunk layout is not (steps, {self.label}): {self._describe(raw)}")
        n, stride = struct.unpack_from("<II", raw, 4 + self._size0)
        (count,) = struct.unpack_from("<I", raw, 4 + self._count)
        if stride != n * self.cols or count != n * self.cols:
            raise BadInputError(f"chunk holds {count} values, layout says {n} x {self.cols}")
        if len(raw) < h + count * self.dtype.itemsize:
            raise BadInputError(f"chunk is truncated: {len(raw)} bytes for {n} x {self.cols} values")
        return np.frombuffer(raw, self.dtype, count, h).reshape(n, self.cols)

    @staticmethod
    def _describe(raw: bytes) -> str:
        """Best-effort (label, size) list of a payload's dimensions, for messages."""
        try:
            (ndim,) = struct.unpack_from("<I", raw, 4)
            o, dims = 8, []
            for _ in range(min(ndim, 8)):
                (ln,) = struct.unpack_from("<I", raw, o)
                label = raw[o + 4 : o + 3 + ln].decode(errors="replace")
                o += 4 + ln
                o += -(o - 4) % 4
                size, _stride = struct.unpack_from("<II", raw, o)
                o += 8
                dims.append((label, size))
            return str(dims)
        except (struct.error, ValueError):
            return f"{len(raw)} unreadable bytes"


# -- a hardware bridge's messages (winder_bridge) ----------------------------------
# The bridge's messages as CDR bytes, ROS-free: what it publishes 1000 times
# a second is written into preallocated buffers, and what ros2_control
# publishes is read without building message objects (rclpy's Python messages
# cost tens of microseconds each; these cost a few).
#
# Layouts (XCDR1 little endian; offsets after the 4-byte encapsulation header;
# primitives aligned to their size from there):
#
# * ``std_msgs/Float64MultiArray`` with an empty layout: uint32 dim count (0),
#   uint32 data_offset (0), uint32 data count n, 4 bytes padding, n float64.
# * ``rosgraph_msgs/Clock``: int32 sec, uint32 nanosec.
# * ``sensor_msgs/JointState``: header (int32 sec, uint32 nanosec, string
#   frame_id), string[] name, float64[] position, float64[] velocity,
#   float64[] effort.

_CLOCK = struct.Struct("<4siI")


def clock_payload(t_ns: int) -> bytes:
    """A ``rosgraph_msgs/Clock`` payload for ``t_ns`` (ns, >= 0)."""
    sec, nsec = divmod(t_ns, 1_000_000_000)
    return _CLOCK.pack(_HEADER, sec, nsec)


class CommandPayload:
    """A ``std_msgs/Float64MultiArray`` of ``n`` values with an empty layout
    (what a ForwardCommandController reads): :attr:`values` is a float64 view
    into the payload, so writing it and :meth:`bytes` is the whole cost."""

    def __init__(self, n: int) -> None:
        self.buf = np.zeros(4 + 16 + 8 * n, dtype=np.uint8)
        self.buf[:4] = np.frombuffer(_HEADER, np.uint8)
        self.buf[4 + 8 : 4 + 12] = np.frombuffer(struct.pack("<I", n), np.uint8)
        self.values: npt.NDArray[np.float64] = self.buf[4 + 16 :].view("<f8")

    def bytes(self) -> bytes:
        return self.buf.tobytes()


def joint_state_names(body: memoryview) -> tuple[list[str], int]:
    """The joint names of a little-endian CDR ``sensor_msgs/JointState`` (its
    body, after the 4-byte encapsulation header) and the offset, aligned to
    4, of the position array's length that follows them; struct.error if
    the body is cut short."""
    off = 8  # stamp
    (flen,) = struct.unpack_from("<I", body, off)
    off += 4 + flen
    off += -off % 4
    (count,) = struct.unpack_from("<I", body, off)
    off += 4
    names = []
    for _ in range(count):
        off += -off % 4
        (slen,) = struct.unpack_from("<I", body, off)
        names.append(bytes(body[off + 4 : off + 3 + slen]).decode("utf-8", "replace"))
        off += 4 + slen
    return names, off + (-off % 4)


class JointStateReader:
    """Reads ``sensor_msgs/JointState`` payloads for a fixed list of joints.

    :meth:`read` returns the stamp (ns) and, for each wanted joint, its
    measured position (NaN where the message does not name it). The
    message's layout (frame id, names, position count) is parsed once and
    reused while the bytes before the positions stay the same, as they do
    from a joint_state_broadcaster; unknown names are ignored."""

    def __init__(self, joints: Sequence[str]) -> None:
        self.joints = list(joints)
        self._prefix = b""  # bytes 12 (after the stamp) .. position data of the known layout
        self._pos_at = 0  # payload offset of the position data
        self._count = 0  # positions in the message
        self._index = np.zeros(len(self.joints), np.int64)  # message index of each wanted joint
        self._present = np.zeros(len(self.joints), bool)
        self._picks: list[int] | None = None  # message index of each wanted joint, if all are named
        self._format = ""

    def read(self, raw: bytes) -> tuple[int, npt.NDArray[np.float64]] | None:
        """(stamp ns, positions of the wanted joints, NaN if absent), or None
        if the payload is not a JointState with one position per name."""
        if not self._layout(raw):
            return None
        sec, nsec = struct.unpack_from("<iI", raw, 4)
        data = np.frombuffer(raw, "<f8", self._count, self._pos_at)
        out = np.full(len(self.joints), np.nan)
        out[self._present] = data[self._index[self._present]]
        return sec * 1_000_000_000 + nsec, out

    def read_all(self, raw: bytes) -> tuple[int, list[float]] | None:
        """As :meth:`read`, as Python floats, but only for a message that
        gives every wanted joint a position, none NaN (None otherwise: use
        :meth:`read`): a handful of joints at 100 Hz costs less without
        numpy's per-call overhead."""
        if not self._layout(raw) or self._picks is None:
            return None
        sec, nsec = struct.unpack_from("<iI", raw, 4)
        values = struct.unpack_from(self._format, raw, self._pos_at)
        picked = [values[i] for i in self._picks]
        if any(v != v for v in picked):  # a NaN: that joint is not measured (read() says so)
            return None
        return sec * 1_000_000_000 + nsec, picked

    def _layout(self, raw: bytes) -> bool:
        """Whether ``raw`` is a little-endian CDR JointState whose layout is
        known (the last one's, reused) or parsed now."""
        if len(raw) < 12 or raw[1] != 1:
            return False
        known = self._prefix and raw.startswith(self._prefix, 12) and len(raw) >= self._end
        return bool(known) or self._parse(raw)

    @property
    def _end(self) -> int:
        return self._pos_at + 8 * self._count

    def _parse(self, raw: bytes) -> bool:
        body = memoryview(raw)[4:]
        try:
            names, off = joint_state_names(body)
            (npos,) = struct.unpack_from("<I", body, off)
            off += 4
            count = len(names)
        except struct.error:
            return False
        if npos != count:
            return False
        if npos:
            off += -off % 8
        if 4 + off + 8 * npos > len(raw):
            return False
        self._pos_at, self._count = 4 + off, npos
        self._prefix = bytes(raw[12 : self._pos_at])
        where = {name: i for i, name in enumerate(names)}
        self._present = np.array([j in where for j in self.joints], bool)
        self._index = np.array([where.get(j, 0) for j in self.joints], np.int64)
        self._picks = [where[j] for j in self.joints] if self._present.all() else None
        self._format = f"<{npos}d"
        return True
