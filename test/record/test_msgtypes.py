"""winder.record.msgtypes: the message types a bag records, made from their
definitions alone, are rosbags' ROS 2 Jazzy types field for field, and give
the same message definition text (what a bag's schema holds, and Foxglove
decodes with). The oracle is rosbags' own Jazzy typestore."""

from __future__ import annotations

from typing import Any

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
    the bytes rclpy's generated class serializes (every field set to a value
    of its own) read back field for field."""
    import importlib
    import json
    import sys
    from pathlib import Path

    from rclpy.serialization import serialize_message
    from rosbags.typesys import get_types_from_msg
    from support.paths import ROOT

    package, _, type_name = name.split("/")
    oracle = get_typestore(Stores.EMPTY)
    for own in OWN:  # its nested own types read from their files too
        text = (ROOT / package / "msg" / f"{own.rsplit('/', 1)[1]}.msg").read_text()
        oracle.register(get_types_from_msg(text, own))
    oracle.register(
        {
            k: v
            for k, v in JAZZY.fielddefs.items()
            if k.startswith(("builtin_interfaces/", "diagnostic_msgs/"))
        }
    )
    small = typestore_for([name])
    assert small.fielddefs[name] == oracle.fielddefs[name]
    generated = json.loads((Path(sys.prefix) / "share" / package / "msg" / f"{type_name}.json").read_text())
    [hashed] = [h["hash_string"] for h in generated["type_hashes"] if h["type_name"] == name]
    assert small.hash_rihs01(name) == hashed

    module = importlib.import_module(f"{package}.msg")
    msg = _filled(getattr(module, type_name)(), module, seed=3)
    back = small.deserialize_cdr(serialize_message(msg), name)
    assert _plain(back) == _plain(msg)


def _filled(msg: Any, module: Any, seed: int) -> Any:
    """``msg`` with each field set to a value of its own (not a default):
    numbers from ``seed`` on, texts naming their field, two items in each
    sequence (messages filled alike)."""
    import diagnostic_msgs.msg

    for i, (field, kind) in enumerate(msg.get_fields_and_field_types().items()):
        n = seed + i
        base = kind.split("<")[0].removeprefix("sequence")
        if kind.startswith("sequence<"):
            inner = kind[len("sequence<") : -1]
            if inner in ("string",):
                value: Any = [f"{field}-a", f"{field}-b"]
            elif inner.startswith(("int", "uint")):
                value = [n, n + 1]
            elif inner == "double":
                value = [n + 0.25, n + 0.5]
            else:
                pkg, _, cls = inner.partition("/")
                where = module if pkg == "winder_interfaces" else diagnostic_msgs.msg
                value = [
                    _filled(getattr(where, cls)(), module, n),
                    _filled(getattr(where, cls)(), module, n + 7),
                ]
        elif kind == "string":
            value = f"{field}-{n}"
        elif kind == "boolean":
            value = True
        elif kind == "double":
            value = n + 0.125
        elif kind.startswith(("int", "uint")):
            value = n
        elif kind == "builtin_interfaces/Time":
            value = type(getattr(msg, field))(sec=n, nanosec=n + 1)
        else:
            raise AssertionError(f"{field}: {kind} (base {base}) is not filled by this test")
        setattr(msg, field, value)
    return msg


def _plain(msg: Any) -> Any:
    """A message (rclpy's or rosbags') as nested dicts and lists."""
    if hasattr(msg, "get_fields_and_field_types"):
        return {f: _plain(getattr(msg, f)) for f in msg.get_fields_and_field_types()}
    if hasattr(msg, "__dataclass_fields__"):
        return {
            f: _plain(getattr(msg, f))
            for f in msg.__dataclass_fields__
            if not f.startswith("_") and not f.isupper()
        }
    if isinstance(msg, (list, tuple)) or type(msg).__name__ in ("ndarray", "array"):
        return [_plain(x) for x in msg]
    if hasattr(msg, "item"):
        return msg.item()
    return msg
