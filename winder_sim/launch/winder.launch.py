"""Launch the winding cell: interp_node -> profile_node -> sim_node.

    ros2 launch winder_sim winder.launch.py profile:=trapezoid turns_per_layer:=40

Every node parameter can be given as a launch argument of the same name; the
job starts as soon as the chain is connected (interp_node's autostart). Use
``namespace:=cell1`` to run several cells on one ROS graph.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from winder.params import INTERP_SPECS, PROFILE_SPECS, SIM_SPECS


def _args(specs):
    return [
        DeclareLaunchArgument(
            name,
            default_value=str(spec.default).lower() if spec.kind is bool else str(spec.default),
            description=spec.help(),
        )
        for name, spec in specs.items()
        if "." not in name
    ]


def _params(specs):
    return [{name: LaunchConfiguration(name) for name in specs if "." not in name}]


def generate_launch_description():
    ns = LaunchConfiguration("namespace")
    return LaunchDescription(
        [
            DeclareLaunchArgument("namespace", default_value="", description="namespace of the cell"),
            *_args(INTERP_SPECS),
            *_args(PROFILE_SPECS),
            *_args(SIM_SPECS),
            Node(
                package="winder_sim",
                executable="sim_node",
                namespace=ns,
                parameters=_params(SIM_SPECS),
                output="screen",
            ),
            Node(
                package="winder_profile",
                executable="profile_node",
                namespace=ns,
                parameters=_params(PROFILE_SPECS),
                output="screen",
            ),
            Node(
                package="winder_interp",
                executable="interp_node",
                namespace=ns,
                parameters=_params(INTERP_SPECS),
                output="screen",
            ),
        ]
    )
