"""The launch descriptions of ``launch/*.launch.py``: ``launch_plan``'s nodes as launch actions.

``launch`` and ``launch_ros`` come with a ROS 2 installation (they are not on PyPI), so they
are imported only when a description is built.
"""

from __future__ import annotations

from typing import Any

from hiros_ros.launch_plan import node_plan, parse_cameras, share_file

__all__ = ["PIPELINE_ARGUMENTS", "pipeline", "single_node"]

PIPELINE_ARGUMENTS = {
    "cameras": ("[k01, k02, k03]", "camera names (topic namespaces), e.g. '[k01, k02]'"),
    "calibration_file": ("", "hiros calibrate's output; empty: the calib node's live result"),
    "use_sim_time": ("false", "true with a /clock source (hiros play, ros2 bag play --clock)"),
    "namespace": ("", "namespace of every node and pipeline topic (e.g. lab1)"),
    "composed": ("false", "true: bridge and stages in one process (the pipeline node)"),
    "input": ("driver", "driver: Azure Kinect driver MarkerArrays; skeletons: SkeletonGroups"),
    "params_file": ("", "a ROS parameter file for any of the nodes (Hi-ROS's style)"),
    "rviz": ("false", "true: start RViz with hiros's view"),
}
"""Launch argument -> (default, description) of pipeline.launch.py."""


def _flag(text: str) -> bool:
    return text.strip().lower() in ("true", "1", "yes")


def _pipeline_nodes(context: Any) -> list[Any]:
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    def value(name: str) -> str:
        return LaunchConfiguration(name).perform(context)

    namespace = value("namespace")
    plan = node_plan(
        parse_cameras(value("cameras")),
        namespace=namespace,
        use_sim_time=_flag(value("use_sim_time")),
        calibration_file=value("calibration_file"),
        composed=_flag(value("composed")),
        camera_input=value("input"),
        rviz_config=share_file("rviz", "hiros.rviz") if _flag(value("rviz")) else "",
    )
    params_file = value("params_file")
    return [
        Node(
            package=spec.package,
            executable=spec.executable,
            name=spec.name,
            namespace=namespace,
            parameters=[*([params_file] if params_file else []), spec.parameters],
            remappings=spec.remappings,
            arguments=spec.arguments,
            output="screen",
        )
        for spec in plan
    ]


def pipeline() -> Any:
    """Every argument of ``PIPELINE_ARGUMENTS``, then the nodes they choose."""
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    from launch import LaunchDescription

    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default, description=text)
                for name, (default, text) in PIPELINE_ARGUMENTS.items()
            ),
            OpaqueFunction(function=_pipeline_nodes),
        ]
    )


def single_node(executable: str) -> Any:
    """One node with its parameter file, as Hi-ROS launches each of its nodes.

    Arguments: ``params_file`` (default: the node's config/<executable>.yaml, which holds every
    parameter with its default: copy and edit it), ``name``, ``namespace``, ``use_sim_time``.
    """
    from launch.actions import DeclareLaunchArgument
    from launch.substitutions import LaunchConfiguration
    from launch_ros.actions import Node

    from launch import LaunchDescription

    config = share_file("config", f"{executable}.yaml")
    arguments = {
        "params_file": (config, f"parameter file of the {executable} node"),
        "name": (executable, "node name (the params file's section must match it)"),
        "namespace": ("", "node namespace"),
        "use_sim_time": ("false", "true with a /clock source"),
    }
    return LaunchDescription(
        [
            *(
                DeclareLaunchArgument(name, default_value=default, description=text)
                for name, (default, text) in arguments.items()
            ),
            Node(
                package="hiros",
                executable=executable,
                name=LaunchConfiguration("name"),
                namespace=LaunchConfiguration("namespace"),
                parameters=[
                    LaunchConfiguration("params_file"),
                    {"use_sim_time": LaunchConfiguration("use_sim_time")},
                ],
                output="screen",
            ),
        ]
    )
