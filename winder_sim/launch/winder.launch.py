"""Launch the winding cell: interp_node -> profile_node -> sim_node.

    ros2 launch winder_sim winder.launch.py profile:=trapezoid turns_per_layer:=40

Every node parameter can be given as a launch argument of the same name, the
sim node's per-axis motor parameters included (``fork.J:=2e-4``); the job
starts as soon as the chain is connected (interp_node's autostart). Use
``namespace:=cell1`` to run several cells on one ROS graph.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from winder.contract.params import INTERP_SPECS, PROFILE_SPECS, SIM_SPECS


def _args(specs):
    return [
        DeclareLaunchArgument(
            name,
            default_value=str(spec.default).lower() if spec.kind is bool else str(spec.default),
            description=spec.help(),
        )
        for name, spec in specs.items()
    ]


def _params(specs):
    # every parameter, the per-axis motor ones too (fork.J:=2e-4)
    return [{name: LaunchConfiguration(name) for name in specs}]


# downstream first: each node waits for its reader, so the job starts when the
# whole chain is up
NODES = (
    ("winder_sim", "sim_node", SIM_SPECS),
    ("winder_profile", "profile_node", PROFILE_SPECS),
    ("winder_interp", "interp_node", INTERP_SPECS),
)


def generate_launch_description():
    ns = LaunchConfiguration("namespace")
    actions = [DeclareLaunchArgument("namespace", default_value="", description="namespace of the cell")]
    for package, executable, specs in NODES:
        actions += _args(specs)
        actions.append(
            Node(
                package=package,
                executable=executable,
                namespace=ns,
                parameters=_params(specs),
                output="screen",
            )
        )
    return LaunchDescription(actions)
