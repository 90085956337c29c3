"""Launch the visualizer node alone with its parameter file, as Hi-ROS launches each node.

    ros2 launch hiros visualizer.launch.py params_file:=my_visualizer.yaml namespace:=hiros
The default file is config/visualizer.yaml (every parameter with its default): copy it and edit.
"""

from hiros_ros.launch_description import single_node


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """One visualizer node."""
    return single_node("visualizer")
