"""hiros_tracker: persistent track ids for every camera detection, in the world frame."""

from hiros_tracker.tracker import Tracker, TrackerParams

__all__ = ["Tracker", "TrackerParams", "main"]


def main(args: list[str] | None = None) -> None:
    """Run the ``tracker`` node (rclpy is imported only here, so the class stays ROS-free)."""
    from hiros_tracker.node import main as node_main

    node_main(args)
