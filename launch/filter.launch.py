"""Launch the filter node alone with its parameter file, as Hi-ROS launches each node.

    ros2 launch hiros filter.launch.py params_file:=my_filter.yaml namespace:=hiros
The default file is config/filter.yaml (every parameter with its default): copy it and edit.
"""

from hiros_ros.launch_description import single_node


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """One filter node."""
    return single_node("filter")
