"""Environment defaults for ROS 2 from PyPI wheels, set before rclpy is imported."""

from __future__ import annotations

import os
import sys
from pathlib import Path


def prepare_ros_environment() -> None:
    """Make the venv's ament index visible when no ROS 2 workspace is sourced.

    With the wheels, everything (messages, rmw, our package) is installed into the venv prefix,
    but nothing sets ``AMENT_PREFIX_PATH`` as sourcing a workspace would; ``ros2 run``-style
    look-ups (config files, executables) need it. A sourced system ROS 2 keeps its own value.
    """
    index = Path(sys.prefix) / "share" / "ament_index" / "resource_index" / "packages"
    if not os.environ.get("AMENT_PREFIX_PATH") and index.is_dir():
        os.environ["AMENT_PREFIX_PATH"] = sys.prefix
