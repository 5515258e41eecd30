"""The sim node's hand-made CDR payloads against rclpy's own serializer (the
reference) and rosbags' strict reader."""

from __future__ import annotations

import numpy as np
import pytest
from geometry_msgs.msg import WrenchStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.serialization import deserialize_message, serialize_message
from rosbags.typesys import Stores, get_typestore
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Int32MultiArray, Int64MultiArray, MultiArrayDimension

from winder.contract.cdr import JointStateEncoder, MultiArrayCodec, WrenchEncoder, encode_clocks
from winder.contract.stream import STEP_COLUMNS, TIMED_COLUMNS

TS = get_typestore(Stores.ROS2_JAZZY)
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
# at least one joint: with none, Fast CDR aligns the empty float64[] fields to 8
# bytes mid-message (a case the sim node never sends)
names = st.lists(
    st.text(st.characters(min_codepoint=97, max_codepoint=122), max_size=9), min_size=1, max_size=5
)


@settings(max_examples=200, deadline=None)
@given(names, st.text(st.characters(min_codepoint=48, max_codepoint=122), max_size=12), st.data())
def test_joint_state_bytes_match_rclpy(joint_names: list[str], frame: str, data: st.DataObject) -> None:
    n = len(joint_names)
    m = data.draw(st.integers(1, 4))
    t_ns = np.array(
        data.draw(st.lists(st.integers(0, 2**31 * 10**9 - 1), min_size=m, max_size=m)), dtype=np.int64
    )
    pos = np.array(data.draw(st.lists(finite, min_size=m * n, max_size=m * n))).reshape(m, n)
    vel = np.array(data.draw(st.lists(finite, min_size=m * n, max_size=m * n))).reshape(m, n)
    out = JointStateEncoder(joint_names, frame).encode(t_ns, pos, vel)
    for i, payload in enumerate(out):
        ref = JointState(name=joint_names, position=pos[i].tolist(), velocity=vel[i].tolist())
        ref.header.frame_id = frame
        ref.header.stamp.sec, ref.header.stamp.nanosec = divmod(int(t_ns[i]), 10**9)
        expected = serialize_message(ref)
        # same layout and length; rclpy leaves its alignment bytes uninitialised
        # (so bytes differ there) and appends 4 of them after the empty effort
        assert len(expected) - len(payload) in (0, 4)
        assert deserialize_message(payload, JointState) == ref
        strict = TS.deserialize_cdr(payload, "sensor_msgs/msg/JointState")
        assert strict.header.frame_id == frame
        assert np.array_equal(strict.velocity, vel[i])


@settings(max_examples=100)
@given(st.lists(st.integers(0, 2**31 * 10**9 - 1), min_size=1, max_size=5))
def test_clock_bytes_match_rclpy(times: list[int]) -> None:
    for t, payload in zip(times, encode_clocks(np.array(times, dtype=np.int64)), strict=True):
        ref = Clock()
        ref.clock.sec, ref.clock.nanosec = divmod(t, 10**9)
        assert payload == serialize_message(ref)


# -- the step stream's chunks ----------------------------------------------------
STEPS = MultiArrayCodec(STEP_COLUMNS, np.int32)
TIMED = MultiArrayCodec(TIMED_COLUMNS, np.int64)


def _reference(rows: np.ndarray, columns: tuple[str, ...], msg_type: type) -> bytes:
    """The chunk as a message object, serialized by rclpy (the reference)."""
    msg = msg_type()
    msg.layout.dim = [
        MultiArrayDimension(label="steps", size=rows.shape[0], stride=rows.size),
        MultiArrayDimension(label=",".join(columns), size=len(columns), stride=len(columns)),
    ]
    msg.data = rows.ravel().tolist()
    return serialize_message(msg)


@settings(max_examples=150, deadline=None)
@given(st.integers(1, 300), st.booleans(), st.data())
def test_step_chunks_round_trip_with_rclpy(n: int, timed: bool, data: st.DataObject) -> None:
    codec, cols, msg_type, bits = (
        (TIMED, TIMED_COLUMNS, Int64MultiArray, 63) if timed else (STEPS, STEP_COLUMNS, Int32MultiArray, 31)
    )
    seed = data.draw(st.integers(0, 2**32 - 1))
    rows = np.random.default_rng(seed).integers(-(2**bits), 2**bits, size=(n, len(cols)))
    payload = codec.encode(rows)
    ref = _reference(rows, cols, msg_type)
    assert len(payload) == len(ref)  # the same layout; padding bytes may differ
    back = deserialize_message(payload, msg_type)
    assert [(d.label, d.size, d.stride) for d in back.layout.dim] == [
        ("steps", n, n * len(cols)),
        (",".join(cols), len(cols), len(cols)),
    ]
    assert np.array_equal(np.asarray(back.data).reshape(n, len(cols)), rows)
    assert np.array_equal(codec.decode(ref), rows)  # and rclpy's bytes decode here
    strict = TS.deserialize_cdr(payload, f"std_msgs/msg/{msg_type.__name__}")
    assert np.array_equal(strict.data.reshape(n, len(cols)), rows)


def test_step_chunk_decode_rejects_other_layouts() -> None:
    rows = np.arange(12, dtype=np.int64).reshape(3, 4)
    with pytest.raises(
        ValueError,
        match=r"^chunk layout is not \(steps, t_ns,segment,feed,fork,pole\): "
        r"\[\('steps', 3\), \('segment,feed,fork,pole', 4\)\]",
    ):
        TIMED.decode(_reference(rows, STEP_COLUMNS, Int64MultiArray))
    with pytest.raises(ValueError, match=r"^chunk layout is not"):
        STEPS.decode(TIMED.encode(np.zeros((2, 5), np.int64)))  # int64 chunk on the int32 topic
    good = TIMED.encode(np.ones((4, 5), np.int64))
    with pytest.raises(ValueError, match=r"^chunk is truncated: \d+ bytes for 4 x 5 values"):
        TIMED.decode(good[:-8])
    lying = bytearray(good)
    lying[4 + TIMED._size0 : 4 + TIMED._size0 + 4] = (5).to_bytes(4, "little")
    with pytest.raises(ValueError, match=r"^chunk holds 20 values, layout says 5 x 5"):
        TIMED.decode(bytes(lying))
    with pytest.raises(ValueError, match=r"^chunk layout is not .*: 3 unreadable bytes"):
        TIMED.decode(b"\x00\x01\x00")
    with pytest.raises(ValueError, match=r"^rows of shape \(4, 4\) must be \(n, 5\)"):
        TIMED.encode(np.zeros((4, 4)))


@settings(max_examples=100, deadline=None)
@given(
    # a frame id as a job id is (a ROS string holds no NUL: rclpy cuts it there)
    st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=20),
    st.lists(st.tuples(st.integers(0, 2**40), st.floats(allow_nan=False, width=64)), min_size=1, max_size=20),
)
def test_wrench_bytes_match_rclpy(frame: str, samples: list[tuple[int, float]]) -> None:
    """winder/tension: the encoder's payload is rclpy's WrenchStamped (its length and
    fields; rclpy leaves its alignment bytes uninitialised), and rosbags reads it."""
    t = np.array([s[0] for s in samples], np.int64)
    fx = np.array([s[1] for s in samples])
    for raw, (t_ns, f) in zip(WrenchEncoder(frame).encode(t, fx), samples, strict=True):
        msg = WrenchStamped()
        msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(t_ns, 1_000_000_000)
        msg.header.frame_id = frame
        msg.wrench.force.x = f
        assert len(raw) == len(serialize_message(msg))
        assert deserialize_message(raw, WrenchStamped) == msg
        strict = TS.deserialize_cdr(raw, "geometry_msgs/msg/WrenchStamped")
        assert strict.header.frame_id == frame and strict.wrench.force.x == f
