"""Launch the winding cell: interp_node -> profile_node -> sim_node.

    ros2 launch winder_sim winder.launch.py profile:=trapezoid turns_per_layer:=40
    ros2 launch winder_sim winder.launch.py \\
        params_file:=$(ros2 pkg prefix winder_sim)/share/winder_sim/jobs/stator_12.yaml fork.J:=2e-4

Every node parameter is a launch argument of the same name: the job fields
and the interp node's settings, the profile node's ramp and its operation
settings (``feed_override``, ``lookahead``), the sim node's settings and
per-axis motor parameters (``fork.J:=2e-4``); ``stall_abort``, which the
interp and the sim node both have, is one argument for both. ``managed`` and
``use_sim_time`` go to all three nodes. ``params_file`` names a ROS 2
parameters file with a section per node, such as the job files installed
under ``share/winder_sim/jobs/``: each node takes its own section.

An argument given on the command line overrides the file; an argument left
out (its default is empty) leaves the file's value, or else the node's own
default, which the argument's description states. The job starts as soon as
the chain is connected (interp_node's ``autostart``). ``namespace:=cell1``
runs a cell beside others on one ROS graph.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch_ros.actions import Node

from winder.contract.params import INTERP_SPECS, OPERATION_SPECS, PROFILE_SPECS, SIM_SPECS
from winder.spec import Spec

# downstream first: each node waits for its reader, so the job starts when the
# whole chain is up
NODES = (
    ("winder_sim", "sim_node", SIM_SPECS),
    ("winder_profile", "profile_node", {**PROFILE_SPECS, **OPERATION_SPECS}),
    ("winder_interp", "interp_node", INTERP_SPECS),
)

#: arguments for every node
COMMON = {
    "managed": Spec(
        "managed", bool, False, "true: every node waits for an orchestrator's configure and activate"
    ),
    "use_sim_time": Spec(
        "use_sim_time",
        bool,
        False,
        "true: every node's ROS clock follows /clock (their own loops run on the steady clock either way)",
    ),
}


def _declare():
    """One argument per parameter name, whichever nodes have it."""
    args = [
        DeclareLaunchArgument("namespace", default_value="", description="namespace of the cell"),
        DeclareLaunchArgument(
            "params_file",
            default_value="",
            description="ROS 2 parameters file with a section per node (a job file); "
            "the arguments given override it",
        ),
    ]
    seen = set()
    for specs in (COMMON, *(specs for _, _, specs in NODES)):
        for name, spec in specs.items():
            if name in seen:
                continue
            seen.add(name)
            args.append(DeclareLaunchArgument(name, default_value="", description=spec.help()))
    return args


def _nodes(context):
    given = context.launch_configurations
    ns = given.get("namespace", "")
    params_file = given.get("params_file", "")
    nodes = []
    for package, executable, specs in NODES:
        # launch hands over text: each value typed, and judged as winder run judges it
        overrides = {
            name: spec.parse(given[name]) for name, spec in {**COMMON, **specs}.items() if given.get(name, "")
        }
        nodes.append(
            Node(
                package=package,
                executable=executable,
                namespace=ns,
                parameters=[params_file, overrides] if params_file else [overrides],
                output="screen",
            )
        )
    return nodes


def generate_launch_description():
    return LaunchDescription([*_declare(), OpaqueFunction(function=_nodes)])
