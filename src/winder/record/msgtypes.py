"""The ROS 2 Jazzy message types a winder bag records, for rosbags.

rosbags' whole Jazzy typestore is some 160 message classes made at import,
through the module chain of every earlier distribution: 0.1 s of every node
process that records a bag. The types winder's recorders write are few;
:func:`typestore_for` makes them alone, from their ``.msg`` definitions
(comments left out), and falls back to the whole store for any other type.
The test suite checks each definition against rosbags' Jazzy store, and
winder's own against its ``.msg`` file. A bag recorded when one of winder's
own types had other fields (a JobDescription before ``operator`` and
``wire_lot``) is read with the definition it holds (:func:`store_for_schemas`).
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import cache
from typing import Any

__all__ = ["DEFINITIONS", "jazzy_store", "store_for_schemas", "typestore_for"]

#: ``package/msg/Name`` -> its ``.msg`` definition in ROS 2 Jazzy, for the
#: types winder's bags hold and the types they are made of
DEFINITIONS = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "builtin_interfaces/msg/Duration": "int32 sec\nuint32 nanosec",
    "std_msgs/msg/Header": "builtin_interfaces/Time stamp\nstring frame_id",
    "std_msgs/msg/String": "string data",
    "std_msgs/msg/MultiArrayDimension": "string label\nuint32 size\nuint32 stride",
    "std_msgs/msg/MultiArrayLayout": "MultiArrayDimension[] dim\nuint32 data_offset",
    "std_msgs/msg/Int64MultiArray": "MultiArrayLayout layout\nint64[] data",
    "std_msgs/msg/UInt64MultiArray": "MultiArrayLayout layout\nuint64[] data",
    "std_msgs/msg/Float64MultiArray": "MultiArrayLayout layout\nfloat64[] data",
    "sensor_msgs/msg/JointState": (
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort"
    ),
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock",
    "geometry_msgs/msg/Vector3": "float64 x\nfloat64 y\nfloat64 z",
    "geometry_msgs/msg/Wrench": "Vector3 force\nVector3 torque",
    "geometry_msgs/msg/WrenchStamped": "std_msgs/Header header\nWrench wrench",
    "diagnostic_msgs/msg/KeyValue": "string key\nstring value",
    "diagnostic_msgs/msg/DiagnosticStatus": (
        "byte OK=0\nbyte WARN=1\nbyte ERROR=2\nbyte STALE=3\n"
        "byte level\nstring name\nstring message\nstring hardware_id\nKeyValue[] values"
    ),
    "diagnostic_msgs/msg/DiagnosticArray": "std_msgs/Header header\nDiagnosticStatus[] status",
    # winder's own (winder_interfaces/msg/*.msg): winder/state, winder/control and winder/job
    # since 2026-11-28 (a DiagnosticStatus, and JSON in a String, before), winder/report
    "winder_interfaces/msg/CellState": (
        "string IDLE=idle\nstring RUNNING=running\nstring PAUSING=pausing\nstring PAUSED=paused\n"
        "string ABORTING=aborting\nstring DONE=done\nstring ABORTED=aborted\nstring FAILED=failed\n"
        "builtin_interfaces/Time stamp\nstring node\nstring state\nstring job_id\nstring run_id\n"
        "uint32 coil\nuint32 layer\nuint32 turn\nfloat64 sim_time_s\nstring message"
    ),
    "winder_interfaces/msg/ControlEvent": (
        "string PAUSE=pause\nstring RESUME=resume\nstring ABORT=abort\nstring OVERRIDE=override\n"
        "string event\nstring source\nstring run_id\nstring job_id\nint64 t_ns\nint64 t_rest_ns\n"
        "int64 steps\nint64 segment\nint64 step\nfloat64 factor\nint64 t_request_ns\n"
        "int64 latency_ns\nfloat64 v\nfloat64 a\nfloat64 stop_distance\nfloat64 v_max\nstring note"
    ),
    "winder_interfaces/msg/JobDescription": (
        "string FORMAT=winder.job/1\nstring format\nstring run_id\nstring job_id\n"
        "diagnostic_msgs/KeyValue[] job\n"
        "bool has_ramp\ndiagnostic_msgs/KeyValue[] ramp\nJobStop[] stops\nfloat64 stop_pause\n"
        "string stop_resume\nstring schedule\nstring job_file_sha256\nstring operator_name\nstring wire_lot\n"
        "string source_bag\n"
        "string source_run_id\nstring[] axes\nfloat64[] joint_step\nfloat64[] step_lengths\n"
        "uint64 total_steps\nJobSegment[] segments"
    ),
    "winder_interfaces/msg/JobReport": (
        "builtin_interfaces/Time stamp\nstring node\nstring state\nstring job_id\nstring run_id\n"
        "uint64 steps_done\nuint64 steps_total\nuint64 steps_missing\nuint32 gaps\n"
        "uint32 chunks_rejected\nfloat64 sim_time_s\nfloat64 wall_time_s\nstring bag\nuint32 errors\n"
        "uint32 stalls\ndiagnostic_msgs/KeyValue[] extra"
    ),
    "winder_interfaces/msg/JobSegment": (
        "string LAYER=layer\nstring INDEX=index\nstring kind\nint64[] start\nint64[] delta\n"
        "uint64 steps\nuint32 pole\nint32 layer"
    ),
    "winder_interfaces/msg/JobStop": ("uint32 segment\nuint64 step"),
    "trajectory_msgs/msg/JointTrajectoryPoint": (
        "float64[] positions\nfloat64[] velocities\nfloat64[] accelerations\nfloat64[] effort\n"
        "builtin_interfaces/Duration time_from_start"
    ),
    "trajectory_msgs/msg/JointTrajectory": (
        "std_msgs/Header header\nstring[] joint_names\nJointTrajectoryPoint[] points"
    ),
}


@cache
def _small() -> Any:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    types: dict[str, Any] = {}
    for name, text in DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def jazzy_store() -> Any:
    """A new store for any type a bag holds: rosbags' Jazzy store, with
    winder's own types (winder_interfaces) registered in it (a caller may
    register more)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    for name, text in DEFINITIONS.items():
        if name.startswith("winder_interfaces/"):
            store.register(get_types_from_msg(text, name))
    return store


_jazzy = cache(jazzy_store)


def typestore_for(msgtypes: Iterable[str]) -> Any:
    """A rosbags typestore that knows every type of ``msgtypes``: the small
    one of :data:`DEFINITIONS` when it has them all, else the whole Jazzy store."""
    return _small() if all(t in DEFINITIONS for t in msgtypes) else _jazzy()


def store_for_schemas(schemas: Iterable[tuple[str, str]]) -> Any:
    """A new store, as :func:`jazzy_store`, for a bag whose channels define
    their types as ``schemas`` ((type, ros2msg text) pairs): each of
    winder's own types that the bag defines otherwise than today (recorded
    by an earlier winder, before a field was added) as the bag defines it,
    so that its messages decode as they were written, never read with
    today's fields (CDR has no field names: a message of another definition
    does not decode, or decodes wrong). A definition that cannot be parsed
    is left to today's."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    today = _jazzy().fielddefs
    theirs: dict[str, Any] = {}
    for msgtype, text in schemas:
        if not msgtype.startswith("winder_interfaces/") or not text:
            continue
        try:
            types = get_types_from_msg(text, msgtype)
        except Exception:  # rosbags' parser errors have no common base
            continue
        if any(today.get(name) != fields for name, fields in types.items()):
            theirs.update(types)
    if not theirs:
        return jazzy_store()
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(theirs)
    for name, text in DEFINITIONS.items():
        if name.startswith("winder_interfaces/") and name not in theirs:
            store.register(get_types_from_msg(text, name))
    return store
