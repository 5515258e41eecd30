"""The step chunks on ``winder/steps`` and ``winder/step_times``: packing rows
into std_msgs multi-arrays with a 2-D layout, unpacking them with the layout
checked, the same rows as raw CDR bytes (what the nodes publish and take), and
taking the chunks already queued on a subscription in one go."""

from __future__ import annotations

import array
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
from rclpy.exceptions import InvalidHandle
from rclpy.subscription import Subscription
from std_msgs.msg import Int32MultiArray, Int64MultiArray, MultiArrayDimension

from winder.contract.cdr import MultiArrayCodec
from winder.contract.stream import STEP_COLUMNS, TIMED_COLUMNS
from winder.errors import BadInputError


def _layout(msg: Int32MultiArray | Int64MultiArray, rows: int, columns: Sequence[str]) -> None:
    cols = len(columns)
    msg.layout.dim = [
        MultiArrayDimension(label="steps", size=rows, stride=rows * cols),
        MultiArrayDimension(label=",".join(columns), size=cols, stride=cols),
    ]
    msg.layout.data_offset = 0


#: The chunks of winder/steps and winder/step_times as serialized payloads:
#: the nodes publish and take these bytes directly (no message objects).
#: Messages a stream callback takes from its subscription's queue by itself.
WAITING_LIMIT = 16


def waiting(sub: Subscription, limit: int = WAITING_LIMIT) -> Iterator[Any]:
    """Messages already queued on ``sub`` (up to ``limit``), taken the way the
    executor takes them. A stream callback that handles them in one go spares
    the executor a round per chunk: rclpy rebuilds its wait set in Python for
    every message it hands out, ~0.1 ms with a node's dozen entities."""
    handle = sub.handle
    take = getattr(handle, "take_message", None)
    if take is None:  # an rclpy without it: the executor hands them out
        return
    for _ in range(limit):
        try:
            with handle:
                got = take(sub.msg_type, sub.raw)
        except InvalidHandle:  # destroyed meanwhile (shutdown)
            return
        if got is None:
            return
        yield got[0]


STEPS_CDR = MultiArrayCodec(STEP_COLUMNS, np.int32)
TIMED_CDR = MultiArrayCodec(TIMED_COLUMNS, np.int64)


def pack_steps(rows: npt.NDArray[np.integer[Any]]) -> Int32MultiArray:
    """(n, 4) [segment, feed, fork, pole] -> Int32MultiArray with a 2-D layout."""
    msg = Int32MultiArray()
    _layout(msg, rows.shape[0], STEP_COLUMNS)
    msg.data = array.array("i", np.ascontiguousarray(rows, dtype=np.int32).tobytes())
    return msg


def pack_timed(rows: npt.NDArray[np.integer[Any]]) -> Int64MultiArray:
    """(n, 5) [t_ns, segment, feed, fork, pole] -> Int64MultiArray."""
    msg = Int64MultiArray()
    _layout(msg, rows.shape[0], TIMED_COLUMNS)
    msg.data = array.array("q", np.ascontiguousarray(rows, dtype=np.int64).tobytes())
    return msg


def unpack(msg: Int32MultiArray | Int64MultiArray, columns: Sequence[str]) -> npt.NDArray[Any]:
    """Rows of a packed chunk; ValueError if its layout is not ``columns``."""
    dims = msg.layout.dim
    cols = len(columns)
    if len(dims) != 2 or dims[1].size != cols or dims[1].label != ",".join(columns):
        raise BadInputError(
            f"chunk layout {[(d.label, d.size) for d in dims]} is not (steps, {','.join(columns)})"
        )
    dtype = np.int32 if isinstance(msg, Int32MultiArray) else np.int64
    data = np.frombuffer(msg.data, dtype=dtype)
    if data.size != dims[0].size * cols:
        raise BadInputError(f"chunk holds {data.size} values, layout says {dims[0].size} x {cols}")
    return data.reshape(dims[0].size, cols)
