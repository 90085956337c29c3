"""Launch the Azure bridge, live calibration, the four stages as separate nodes and a visualizer.

For system ROS 2 installations (the `launch` package is not on PyPI):
    ros2 launch hiros pipeline.launch.py calibration_file:=calib.yaml cameras:="[k01, k02]"
Use `ros2 run hiros pipeline` instead for all stages composed in one process.
"""

from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from launch import LaunchDescription


def generate_launch_description() -> LaunchDescription:
    """Bridge -> calib -> tracker -> merger -> optimizer -> filter -> visualizer."""
    calibration = LaunchConfiguration("calibration_file")
    cameras = LaunchConfiguration("cameras")
    nodes = [
        Node(package="hiros", executable="azure_bridge", parameters=[{"cameras": cameras}]),
        Node(package="hiros", executable="calib", parameters=[{"calibration_file": calibration}]),
        Node(package="hiros", executable="tracker", parameters=[{"calibration_file": calibration}]),
        Node(package="hiros", executable="merger"),
        Node(package="hiros", executable="optimizer"),
        Node(package="hiros", executable="filter"),
        Node(package="hiros", executable="visualizer"),
    ]
    return LaunchDescription(
        [
            DeclareLaunchArgument("calibration_file", default_value=""),
            DeclareLaunchArgument("cameras", default_value="[k01, k02, k03]"),
            *nodes,
        ]
    )
