"""A real two-process ROS 2 exchange: rclpy message objects on one side, raw bytes through the
hiros codec on the other; every group must come back exactly."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros
HERE = Path(__file__).resolve().parent


def test_rclpy_publisher_and_raw_codec_node_round_trip_exactly(ros_env: dict[str, str]) -> None:
    pytest.importorskip("hiros_skeleton_msgs.msg")
    echo = subprocess.Popen(
        [sys.executable, str(HERE / "echo_node.py")],
        env=ros_env,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    try:
        client = subprocess.run(
            [sys.executable, str(HERE / "rclpy_client.py")],
            env=ros_env,
            capture_output=True,
            text=True,
            timeout=90,
            check=False,
        )
    finally:
        echo.terminate()
        echo_output, _ = echo.communicate(timeout=30)
    assert client.returncode == 0, client.stdout + client.stderr + echo_output
    assert "sent 20 received 20 exact 20" in client.stdout
    assert "Traceback" not in echo_output
