"""Launch the merger node alone with its parameter file, as Hi-ROS launches each node.

    ros2 launch hiros merger.launch.py params_file:=my_merger.yaml namespace:=hiros
The default file is config/merger.yaml (every parameter with its default): copy it and edit.
"""

from hiros_ros.launch_description import single_node


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """One merger node."""
    return single_node("merger")
