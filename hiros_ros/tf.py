"""TF messages from ``hiros_core.frames.StaticTransform`` edges (the calib and visualizer nodes)."""

from __future__ import annotations

from collections.abc import Iterable

from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from tf2_msgs.msg import TFMessage

from hiros_core.frames import StaticTransform

__all__ = ["tf_message"]


def tf_message(edges: Iterable[StaticTransform], stamp: Time) -> TFMessage:
    """One TFMessage holding every edge, all stamped ``stamp``."""
    transforms = []
    for edge in edges:
        t = TransformStamped()
        t.header.stamp = stamp
        t.header.frame_id = edge.parent
        t.child_frame_id = edge.child
        translation, rotation = t.transform.translation, t.transform.rotation
        translation.x, translation.y, translation.z = (float(v) for v in edge.translation)
        rotation.x, rotation.y, rotation.z, rotation.w = (float(v) for v in edge.rotation)
        transforms.append(t)
    return TFMessage(transforms=transforms)
