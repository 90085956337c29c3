"""hiros_visualizer: coloured skeleton markers for any SkeletonGroup topic, and their overlays."""

from hiros_visualizer.markers import (
    VisualizerParams,
    encode_skeleton_markers,
    id_color,
    skeleton_markers,
)
from hiros_visualizer.overlays import (
    Drawing,
    OverlayParams,
    joint_transforms,
    overlays_from_names,
)

__all__ = [
    "Drawing",
    "OverlayParams",
    "VisualizerParams",
    "encode_skeleton_markers",
    "id_color",
    "joint_transforms",
    "main",
    "overlays_from_names",
    "skeleton_markers",
]


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros visualizer`` (rclpy is imported only here)."""
    from hiros_visualizer.node import main as node_main

    node_main(args)
