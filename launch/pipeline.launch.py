"""Launch hiros: Azure bridge, live calibration, the four stages and a visualizer.

For system ROS 2 installations (the `launch` package is not on PyPI):
    ros2 launch hiros pipeline.launch.py cameras:="[k01, k02]" calibration_file:=calib.yaml
    ros2 launch hiros pipeline.launch.py composed:=true use_sim_time:=true namespace:=lab1
    ros2 launch hiros pipeline.launch.py rviz:=true
    ros2 launch hiros pipeline.launch.py --show-args      # every argument with its description
`composed:=true` runs the bridge and the stages in one process (the pipeline node).
"""

from hiros_ros.launch_description import pipeline


def generate_launch_description():  # noqa: ANN201 - launch.LaunchDescription
    """Bridge -> calib -> tracker -> merger -> optimizer -> filter -> visualizer."""
    return pipeline()
