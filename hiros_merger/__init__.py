"""hiros_merger: one skeleton per person, fused from every camera's detections of its track."""

from hiros_merger.merger import Merger, MergerParams

__all__ = ["Merger", "MergerParams", "main"]


def main(args: list[str] | None = None) -> None:
    """Run the ``merger`` node (rclpy is imported only here, so the class stays ROS-free)."""
    from hiros_merger.node import main as node_main

    node_main(args)
