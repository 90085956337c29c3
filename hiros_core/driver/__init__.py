"""hiros_core.driver: the Azure Kinect driver's ``body_tracking_data`` MarkerArray <-> the model.

The driver (Azure_Kinect_ROS_Driver) publishes, for every body-tracking frame, one
``visualization_msgs/MarkerArray`` holding one SPHERE marker per joint of every body:

* marker id = body id × 100 + joint index (k4abt order), so a frame has bodies × 32 markers;
* every marker carries the frame's stamp and the frame ``<prefix>depth_camera_link``;
* the pose is the joint position in metres and the joint orientation (x, y, z, w);
* some driver forks write the joint confidence level (k4abt: 0 none, 1 low, 2 medium,
  3 high) as an integer in ``marker.text``.

Conventions of this module beyond the driver's:

* confidences in the model are levels divided by ``confidence_levels`` (3 for k4abt), so HIGH
  is 1.0 and NONE 0.0; a marker without a level gives NaN;
* an unknown orientation is written as the all-zero quaternion, which viewers treat as
  "no orientation" (identity), and read back as NaN;
* a layout other than the Azure Kinect's is named in ``marker.ns`` (``kinect_v2``), so a
  recording converted from another device reads back with the right joints; a namespace that
  names a built-in layout overrides the bridge's configured layout.

``DriverBridge`` (``bridge``) is the stage the bridge nodes and the recording reader share;
the same class, configured by a YAML file, reads other drivers that publish one marker per joint
(another id stride, joint-major ids, another joint order, millimetres). ``markers`` holds the
driver's vocabulary and the inverse, ``group_to_driver_markers``; ``batch`` and ``kernels`` read
a recording's driver messages a chunk at a time.
"""

from __future__ import annotations

from hiros_core.driver.bridge import DriverBridge, load_bridge_params, warm_up
from hiros_core.driver.markers import (
    ADD,
    DELETE,
    DELETEALL,
    DRIVER_LIFETIME_NS,
    JOINT_SCALE,
    SPHERE,
    group_to_driver_markers,
)
from hiros_core.driver.params import DriverBridgeParams

__all__ = [
    "ADD",
    "DELETE",
    "DELETEALL",
    "DRIVER_LIFETIME_NS",
    "JOINT_SCALE",
    "SPHERE",
    "DriverBridge",
    "DriverBridgeParams",
    "group_to_driver_markers",
    "load_bridge_params",
    "warm_up",
]
