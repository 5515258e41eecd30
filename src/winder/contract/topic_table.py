"""Every fact about each of the cell's topics, in one row (ROS-free).

A topic's name, type, QoS, the role whose node alone publishes it, whether
the cell's nodes trust only that node with it, whether a live view shows it,
which bags record it and how it shows a node's part on the graph: once
here, and every other table derived from :data:`TOPICS` —
:data:`winder.contract.qos.TOPIC_QOS`, :data:`winder.contract.trust.OWNERS`,
``SHOWN`` and ``SIGNS``, the consumer's, the simulator's and the drivers'
recorded topics, the live view's channels. docs/CONTRACT.md §2 is its
table, and a test holds the two equal. A new topic is one row here (and
its name in :mod:`winder.contract.topics`).
"""

from __future__ import annotations

from dataclasses import dataclass

from winder.contract.topics import (
    TOPIC_CLOCK,
    TOPIC_CONTROL,
    TOPIC_DIAGNOSTICS,
    TOPIC_JOB,
    TOPIC_JOINT_COMMANDS,
    TOPIC_JOINT_STATES,
    TOPIC_PATH,
    TOPIC_PROFILE_CONFIG,
    TOPIC_PROGRESS,
    TOPIC_READY,
    TOPIC_REPORT,
    TOPIC_SIM_CONFIG,
    TOPIC_STATE,
    TOPIC_STEP_TIMES,
    TOPIC_STEPS,
    TOPIC_TENSION,
)

__all__ = ["BY_NAME", "EVERY", "PACED", "ROLES", "SIM", "TOPICS", "Topic", "recorded"]

#: the cell's roles (winder.contract.trust.ROLE_NAMES says them in words)
ROLES = ("interp", "profile", "consumer")
#: which recordings hold a topic: every consumer's bag; a paced consumer's
#: (the simulator's and every driver's: it makes the time and the joints);
#: the simulator's alone (the wire it models)
EVERY, PACED, SIM = "every", "paced", "sim"


@dataclass(frozen=True)
class Topic:
    """One of the cell's topics."""

    #: in the cell's namespace (``winder/job``), or global (``/diagnostics``)
    name: str
    #: its message type, ``package/msg/Type``
    type: str
    #: its QoS profile's name in :data:`winder.contract.qos.PROFILES`
    qos: str
    #: the role whose node alone publishes it ("": several do, each saying who it is in the message)
    owner: str = ""
    #: the cell's nodes act on it, and only from its owner's node (:data:`winder.contract.trust.OWNERS`)
    trusted: bool = False
    #: a live view (``winder view``, ``winder run --foxglove``) serves it
    shown: bool = True
    #: its key in the recordings that hold it ("": none does)
    key: str = ""
    #: which recordings hold it: :data:`EVERY`, :data:`PACED` or :data:`SIM`
    kept: str = ""
    #: its owner's publishing it shows that node's part on the graph
    published_sign: bool = False
    #: the role whose reading it shows that node's part ("" none)
    read_sign: str = ""


WI, STD, DIAG, SENSOR = "winder_interfaces/msg/", "std_msgs/msg/", "diagnostic_msgs/msg/", "sensor_msgs/msg/"

#: the cell's topics, in the order docs/CONTRACT.md §2 lists them (the fields: name, type,
#: qos, owner, trusted, shown, key, kept, published_sign, read_sign)
TOPICS: tuple[Topic, ...] = (
    Topic(TOPIC_JOB, WI + "JobDescription", "latched", "interp", True, True, "job", EVERY, True),
    Topic(TOPIC_STEPS, STD + "Int32MultiArray", "stream", "interp", True, False, published_sign=True),
    Topic(
        TOPIC_STEP_TIMES,
        STD + "Int64MultiArray",
        "stream",
        "profile",
        True,
        False,
        "step_times",
        EVERY,
        True,
        "consumer",
    ),
    Topic(
        TOPIC_PATH,
        "trajectory_msgs/msg/JointTrajectory",
        "latched",
        "profile",
        True,
        True,
        "path",
        EVERY,
        True,
    ),
    Topic(TOPIC_PROFILE_CONFIG, STD + "String", "latched", "profile", True, True, "profile_config", EVERY),
    Topic(
        TOPIC_CONTROL,
        WI + "ControlEvent",
        "events",
        "profile",
        True,
        True,
        "control",
        EVERY,
        True,
    ),
    Topic(TOPIC_READY, DIAG + "KeyValue", "latched", shown=False),
    Topic(TOPIC_PROGRESS, DIAG + "KeyValue", "state", "consumer", True, True, published_sign=True),
    Topic(TOPIC_SIM_CONFIG, STD + "String", "latched", "consumer", True, True, "sim_config", EVERY),
    Topic(TOPIC_STATE, WI + "CellState", "latched", "consumer", True, True, "state", EVERY),
    Topic(TOPIC_REPORT, WI + "JobReport", "latched", "consumer", False, True, "report", EVERY),
    Topic(
        TOPIC_JOINT_COMMANDS,
        SENSOR + "JointState",
        "state",
        "consumer",
        False,
        True,
        "joint_commands",
        PACED,
    ),
    Topic(
        TOPIC_JOINT_STATES,
        SENSOR + "JointState",
        "state",
        "consumer",
        False,
        True,
        "joint_states",
        PACED,
    ),
    Topic(TOPIC_TENSION, "geometry_msgs/msg/WrenchStamped", "state", "consumer", False, True, "tension", SIM),
    Topic(TOPIC_CLOCK, "rosgraph_msgs/msg/Clock", "clock", "consumer", False, True, "clock", PACED),
    Topic(TOPIC_DIAGNOSTICS, DIAG + "DiagnosticArray", "diagnostics", key="diagnostics", kept=EVERY),
)

#: each topic's row by its name
BY_NAME = {t.name: t for t in TOPICS}


def recorded(*kept: str) -> dict[str, tuple[str, str]]:
    """The topics the recordings ``kept`` hold: key -> (name, type), as a
    consumer's ``topics`` take them."""
    return {t.key: (t.name, t.type) for t in TOPICS if t.key and t.kept in kept}
