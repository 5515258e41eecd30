"""Who sent a message: every message a winder node acts on is taken with its
publisher's GID, so the node can ask the graph which node published it
(:class:`winder.ros.peers.Peers`) instead of believing a name in the payload.

rclpy (Jazzy) hands a callback the message and a ``MessageInfo`` without the
publisher's GID, although rmw's ``rmw_message_info_t`` carries it. So a
subscription made with :func:`attributed` is taken here, through rcl's own
``rcl_take_serialized_message`` (ctypes, on the library rclpy has loaded): the
callback gets the serialized payload and the 16-byte GID. The executor of a
winder process (:class:`SenderExecutor`, used by :func:`winder.ros.spin.spin`)
takes these subscriptions this way; :func:`waiting` takes the ones already
queued in one go, the same way.
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import rclpy
from rclpy.exceptions import InvalidHandle
from rclpy.executors import SingleThreadedExecutor, await_or_execute
from rclpy.node import Node
from rclpy.qos import QoSProfile
from rclpy.subscription import Subscription

__all__ = ["GID_SIZE", "SenderExecutor", "attributed", "waiting"]

#: RMW_GID_STORAGE_SIZE of Jazzy's rmw
GID_SIZE = 16
#: rcl's return codes used here
_RCL_RET_OK = 0
_RCL_RET_SUBSCRIPTION_TAKE_FAILED = 401


class _Allocator(ctypes.Structure):
    _fields_ = [
        ("allocate", ctypes.c_void_p),
        ("deallocate", ctypes.c_void_p),
        ("reallocate", ctypes.c_void_p),
        ("zero_allocate", ctypes.c_void_p),
        ("state", ctypes.c_void_p),
    ]


class _Bytes(ctypes.Structure):  # rcutils_uint8_array_t (rcl_serialized_message_t)
    _fields_ = [
        ("buffer", ctypes.POINTER(ctypes.c_uint8)),
        ("buffer_length", ctypes.c_size_t),
        ("buffer_capacity", ctypes.c_size_t),
        ("allocator", _Allocator),
    ]


class _Gid(ctypes.Structure):  # rmw_gid_t
    _fields_ = [("implementation_identifier", ctypes.c_char_p), ("data", ctypes.c_uint8 * GID_SIZE)]


class _Info(ctypes.Structure):  # rmw_message_info_t
    _fields_ = [
        ("source_timestamp", ctypes.c_int64),
        ("received_timestamp", ctypes.c_int64),
        ("publication_sequence_number", ctypes.c_uint64),
        ("reception_sequence_number", ctypes.c_uint64),
        ("publisher_gid", _Gid),
        ("from_intra_process", ctypes.c_bool),
    ]


class _ErrorString(ctypes.Structure):  # rcutils_error_string_t
    _fields_ = [("str", ctypes.c_char * 1024)]


def _libraries() -> tuple[Any, Any]:
    """librcl and librcutils as rclpy loaded them (the wheels keep them in
    ``<prefix>/lib``, three levels above the rclpy package)."""
    lib = Path(rclpy.__file__).resolve().parents[3]
    rcl = ctypes.CDLL(str(lib / "librcl.so"))
    rcutils = ctypes.CDLL(str(lib / "librcutils.so"))
    rcl.rcl_take_serialized_message.argtypes = [
        ctypes.c_void_p,
        ctypes.POINTER(_Bytes),
        ctypes.POINTER(_Info),
        ctypes.c_void_p,
    ]
    rcl.rcl_take_serialized_message.restype = ctypes.c_int
    rcutils.rcutils_get_default_allocator.restype = _Allocator
    rcutils.rcutils_uint8_array_init.argtypes = [
        ctypes.POINTER(_Bytes),
        ctypes.c_size_t,
        ctypes.POINTER(_Allocator),
    ]
    rcutils.rcutils_uint8_array_init.restype = ctypes.c_int
    rcutils.rcutils_uint8_array_fini.argtypes = [ctypes.POINTER(_Bytes)]
    rcutils.rcutils_uint8_array_fini.restype = ctypes.c_int
    rcutils.rcutils_get_error_string.restype = _ErrorString
    rcutils.rcutils_reset_error.restype = None
    return rcl, rcutils


_RCL, _RCUTILS = _libraries()


class _Taker:
    """Takes one attributed subscription's messages: a serialized buffer of
    its own (grown by rmw as needed, freed with the taker)."""

    def __init__(self, sub: Subscription) -> None:
        self.sub = sub
        self.buf = _Bytes()
        self.info = _Info()
        allocator = _RCUTILS.rcutils_get_default_allocator()
        if _RCUTILS.rcutils_uint8_array_init(ctypes.byref(self.buf), 1 << 12, ctypes.byref(allocator)) != 0:
            raise MemoryError("cannot allocate a serialized message buffer")

    def __del__(self) -> None:
        if _RCUTILS is not None and self.buf.buffer:
            _RCUTILS.rcutils_uint8_array_fini(ctypes.byref(self.buf))

    def take(self) -> tuple[bytes, bytes] | None:
        """The next queued message and its publisher's GID, or None. Call
        inside ``with sub.handle`` (the handle is alive)."""
        ret = _RCL.rcl_take_serialized_message(
            self.sub.handle.pointer, ctypes.byref(self.buf), ctypes.byref(self.info), None
        )
        if ret == _RCL_RET_SUBSCRIPTION_TAKE_FAILED:
            _RCUTILS.rcutils_reset_error()
            return None
        if ret != _RCL_RET_OK:
            why = _RCUTILS.rcutils_get_error_string().str.decode(errors="replace")
            _RCUTILS.rcutils_reset_error()
            raise RuntimeError(f"rcl_take_serialized_message on {self.sub.topic_name}: {ret} {why}")
        raw = ctypes.string_at(self.buf.buffer, self.buf.buffer_length)
        return raw, bytes(self.info.publisher_gid.data)


def attributed(
    node: Node,
    msg_type: Any,
    topic: str,
    callback: Callable[[bytes, bytes], None],
    qos: QoSProfile,
    **kwargs: Any,
) -> Subscription:
    """A subscription whose callback gets ``(serialized payload, publisher
    GID)``. Only a :class:`SenderExecutor` hands its messages out."""
    sub = node.create_subscription(msg_type, topic, callback, qos, raw=True, **kwargs)  # type: ignore[arg-type]
    sub.winder_taker = _Taker(sub)  # type: ignore[attr-defined]
    return sub


def waiting(sub: Subscription, limit: int = 16) -> Iterator[tuple[bytes, bytes]]:
    """Messages already queued on an :func:`attributed` subscription (up to
    ``limit``) with their publishers' GIDs. A stream callback that handles
    them in one go spares the executor a round per chunk: rclpy rebuilds its
    wait set in Python for every message it hands out."""
    taker: _Taker = sub.winder_taker  # type: ignore[attr-defined]
    for _ in range(limit):
        try:
            with sub.handle:
                got = taker.take()
        except InvalidHandle:  # destroyed meanwhile (shutdown)
            return
        if got is None:
            return
        yield got


class SenderExecutor(SingleThreadedExecutor):
    """rclpy's single-threaded executor, but the messages of an
    :func:`attributed` subscription are taken with their publisher's GID."""

    def __init__(self, **kwargs: Any) -> None:
        # rclpy's finaliser reads it: a signal that shuts the context down while
        # __init__ runs would leave it unset (an AttributeError printed at exit)
        self._sigint_gc = None  # type: ignore[assignment]
        super().__init__(**kwargs)

    def _take_subscription(self, sub: Subscription) -> Any:
        taker: _Taker | None = getattr(sub, "winder_taker", None)
        if taker is None:
            return super()._take_subscription(sub)  # type: ignore[no-untyped-call]
        try:
            with sub.handle:
                got = taker.take()
        except InvalidHandle:
            return None
        if got is None:
            return None

        async def _execute() -> None:
            await await_or_execute(sub.callback, *got)

        return _execute
