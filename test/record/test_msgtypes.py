"""winder.record.msgtypes: the message types a bag records, made from their
definitions alone, are rosbags' ROS 2 Jazzy types field for field, and give
the same message definition text (what a bag's schema holds, and Foxglove
decodes with). The oracle is rosbags' own Jazzy typestore."""

from __future__ import annotations

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from winder.record.msgtypes import DEFINITIONS, typestore_for

JAZZY = get_typestore(Stores.ROS2_JAZZY)


#: winder's own types (winder_interfaces), not Jazzy's
OWN = sorted(n for n in DEFINITIONS if n.startswith("winder_interfaces/"))


@pytest.mark.parametrize("name", sorted(set(DEFINITIONS) - set(OWN)))
def test_each_type_is_jazzys(name: str) -> None:
    small = typestore_for([name])
    assert "geometry_msgs/msg/Twist" not in small.fielddefs  # the small store, not a fallback to Jazzy's
    assert small.fielddefs[name] == JAZZY.fielddefs[name]
    assert small.generate_msgdef(name, ros_version=2) == JAZZY.generate_msgdef(name, ros_version=2)


def test_the_small_store_serializes_as_jazzys() -> None:
    """A JointState with every field set, and a DiagnosticArray, round-trip
    through the small store to the bytes the Jazzy store makes."""
    small = typestore_for(DEFINITIONS)
    for store_a, store_b in ((small, JAZZY), (JAZZY, small)):
        t = store_a.types
        js = t["sensor_msgs/msg/JointState"](
            header=t["std_msgs/msg/Header"](
                stamp=t["builtin_interfaces/msg/Time"](sec=3, nanosec=7), frame_id="f"
            ),
            name=["fork", "feed"],
            position=np.array([1.5, -2.0]),
            velocity=np.array([0.25, 0.0]),
            effort=np.array([], dtype=float),
        )
        data = store_a.serialize_cdr(js, "sensor_msgs/msg/JointState")
        back = store_b.deserialize_cdr(data, "sensor_msgs/msg/JointState")
        assert store_b.serialize_cdr(back, "sensor_msgs/msg/JointState") == data


def test_another_type_gets_the_whole_store() -> None:
    assert "geometry_msgs/msg/Twist" not in DEFINITIONS
    store = typestore_for(["sensor_msgs/msg/JointState", "geometry_msgs/msg/Twist"])
    assert "geometry_msgs/msg/Twist" in store.fielddefs


@pytest.mark.parametrize("name", OWN)
def test_each_own_type_is_its_msg_files(name: str) -> None:
    """winder's own types: as rosbags reads their .msg file in winder_interfaces
    (comments and all), with the type hash rosidl generated into the venv, and
    the bytes rclpy's generated class serializes read back field for field."""
    import json
    import sys
    from pathlib import Path

    from rclpy.serialization import serialize_message
    from rosbags.typesys import get_types_from_msg
    from support.paths import ROOT

    package, _, type_name = name.split("/")
    text = (ROOT / package / "msg" / f"{type_name}.msg").read_text()
    oracle = get_typestore(Stores.EMPTY)
    oracle.register(get_types_from_msg(text, name))
    oracle.register({k: v for k, v in JAZZY.fielddefs.items() if k.startswith("builtin_interfaces/")})
    small = typestore_for([name])
    assert small.fielddefs[name] == oracle.fielddefs[name]
    generated = json.loads((Path(sys.prefix) / "share" / package / "msg" / f"{type_name}.json").read_text())
    [hashed] = [h["hash_string"] for h in generated["type_hashes"] if h["type_name"] == name]
    assert small.hash_rihs01(name) == hashed
    from winder_interfaces.msg import CellState

    msg = CellState(node="cell1/axes", state=CellState.PAUSED, run_id="r_1", coil=2, layer=3, turn=41)
    msg.sim_time_s, msg.stamp.sec = 12.5, 7
    back = small.deserialize_cdr(serialize_message(msg), name)
    assert (back.node, back.state, back.run_id, back.coil, back.layer, back.turn) == (
        "cell1/axes",
        "paused",
        "r_1",
        2,
        3,
        41,
    )
    assert (back.sim_time_s, back.stamp.sec) == (12.5, 7)
