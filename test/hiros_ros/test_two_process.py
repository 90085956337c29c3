"""A real two-process ROS 2 exchange: rclpy message objects on one side, raw bytes through the
hiros codec on the other; every group must come back exactly."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros
HERE = Path(__file__).resolve().parent


def test_rclpy_publisher_and_raw_codec_node_round_trip_exactly(ros_processes) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    ros_processes.command([sys.executable, str(HERE / "echo_node.py")])
    client = ros_processes.client(HERE / "rclpy_client.py", timeout=90)
    echo_output = ros_processes.stop()
    assert client.returncode == 0, client.stdout + client.stderr + echo_output
    assert "sent 20 received 20 exact 20" in client.stdout
    assert "Traceback" not in echo_output
