"""hiros_azure_bridge: the bridge nodes, body-tracking drivers' MarkerArrays -> SkeletonGroup.

The conversion itself is ``hiros_core.driver`` (ROS-free); its public names are also here.
"""

from hiros_core.driver import (
    DriverBridge,
    DriverBridgeParams,
    group_to_driver_markers,
    load_bridge_params,
)

__all__ = [
    "DriverBridge",
    "DriverBridgeParams",
    "generic_main",
    "group_to_driver_markers",
    "load_bridge_params",
    "main",
]


def main(args: list[str] | None = None) -> None:
    """``ros2 run hiros azure_bridge`` (rclpy is imported only here)."""
    from hiros_azure_bridge.node import main as node_main

    node_main(args)


def generic_main(args: list[str] | None = None) -> None:
    """``ros2 run hiros generic_bridge``."""
    from hiros_azure_bridge.node import generic_main as node_main

    node_main(args)
