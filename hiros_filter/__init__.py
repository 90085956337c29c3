"""hiros_filter: causal smoothing of each person's joints, with velocities and accelerations."""

from hiros_filter.filter import Filter, FilterParams

__all__ = ["Filter", "FilterParams", "main"]


def main(args: list[str] | None = None) -> None:
    """Run the ``filter`` node (rclpy is imported only here, so the class stays ROS-free)."""
    from hiros_filter.node import main as node_main

    node_main(args)
