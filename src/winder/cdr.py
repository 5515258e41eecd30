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
"""

from __future__ import annotations

import struct
from collections.abc import Sequence

import numpy as np
import numpy.typing as npt

__all__ = ["JointStateEncoder", "encode_clocks"]

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

    def align(self, n: int) -> None:
        self.buf += b"\x00" * (-len(self.buf) % n)

    def u32(self, v: int) -> int:
        self.align(4)
        at = len(self.buf)
        self.buf += struct.pack("<I", v)
        return at

    def string(self, s: str) -> None:
        data = s.encode() + b"\x00"
        self.u32(len(data))
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
