"""Launch the calib node alone with its parameter file, as Hi-ROS launches each node.

    ros2 launch hiros calib.launch.py params_file:=my_calib.yaml namespace:=hiros
The default file is config/calib.yaml (every parameter with its default): copy it and edit.
"""

from hiros_ros.launch_description import single_node


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """One calib node."""
    return single_node("calib")
