"""The driver format's public names where they stood before they moved to ``hiros_core.driver``.

The conversion is ROS-free and the recording reader needs it, so it lives in ``hiros_core``; this
package keeps the bridge nodes.
"""

from hiros_core.driver import (
    ADD,
    DELETE,
    DELETEALL,
    SPHERE,
    DriverBridge,
    DriverBridgeParams,
    group_to_driver_markers,
    load_bridge_params,
)

__all__ = [
    "ADD",
    "DELETE",
    "DELETEALL",
    "SPHERE",
    "DriverBridge",
    "DriverBridgeParams",
    "group_to_driver_markers",
    "load_bridge_params",
]
