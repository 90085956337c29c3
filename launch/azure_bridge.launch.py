"""Launch the azure_bridge node alone with its parameter file, as Hi-ROS launches each node.

    ros2 launch hiros azure_bridge.launch.py params_file:=my_azure_bridge.yaml namespace:=hiros
The default file is config/azure_bridge.yaml (every parameter with its default): copy it and edit.
"""

from hiros_ros.launch_description import single_node


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """One azure_bridge node."""
    return single_node("azure_bridge")
