"""hiros_azure_bridge: body-tracking drivers' MarkerArrays -> SkeletonGroup."""

from hiros_azure_bridge.driver_format import (
    DriverBridge,
    DriverBridgeParams,
    group_to_driver_markers,
    load_bridge_params,
)

__all__ = [
    "DriverBridge",
    "DriverBridgeParams",
    "group_to_driver_markers",
    "load_bridge_params",
]
