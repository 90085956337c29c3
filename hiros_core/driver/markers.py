"""The Azure Kinect driver's marker vocabulary, and the MarkerArray it publishes for a group.

``group_to_driver_markers`` is the inverse of ``DriverBridge``: the simulator, ``hiros
convert`` and the tests write driver recordings with it.
"""

from __future__ import annotations

import math

import numpy as np

from hiros_core.codec import MarkerArrayData
from hiros_core.errors import CodecError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import SkeletonGroup

__all__ = [
    "ADD",
    "DELETE",
    "DELETEALL",
    "DRIVER_LIFETIME_NS",
    "JOINT_SCALE",
    "SPHERE",
    "group_to_driver_markers",
]

SPHERE = 2
"""``visualization_msgs/Marker.SPHERE``."""
ADD = 0
"""``Marker.ADD`` (also ``MODIFY``)."""
DELETE = 2
"""``Marker.DELETE``: remove one marker."""
DELETEALL = 3
"""``Marker.DELETEALL``: remove every marker of the namespace (the driver's "no bodies")."""

DRIVER_LIFETIME_NS = 250_000_000
"""The driver gives markers 0.25 s of life so that RViz does not flicker at 5 Hz."""
JOINT_SCALE = 0.05
"""Sphere diameter the driver uses, metres."""

# One colour per body id (id modulo the palette), like the driver, so people keep a colour.
_PALETTE = np.array(
    [
        [0.90, 0.20, 0.20, 1.0],
        [0.20, 0.60, 0.90, 1.0],
        [0.30, 0.80, 0.30, 1.0],
        [0.95, 0.75, 0.10, 1.0],
        [0.70, 0.35, 0.85, 1.0],
        [0.10, 0.80, 0.80, 1.0],
        [0.95, 0.50, 0.15, 1.0],
        [0.60, 0.60, 0.60, 1.0],
    ],
    dtype=np.float32,
)


def group_to_driver_markers(
    group: SkeletonGroup,
    *,
    id_stride: int = 100,
    confidence_levels: int = 3,
    lifetime_ns: int = DRIVER_LIFETIME_NS,
) -> MarkerArrayData:
    """The MarkerArray the Azure Kinect driver would publish for ``group``.

    One SPHERE marker per present joint of every skeleton: id ``skeleton.id * id_stride +
    joint``, the group's stamp and frame, the joint pose (all-zero quaternion when the
    orientation is unknown), a colour per body, and the confidence level
    ``round(confidence * confidence_levels)`` as text when the confidence is known. A group
    without skeletons gives an empty array, as the driver publishes when nobody is in view.

    Raises:
        CodecError: a skeleton id is negative or a layout has more joints than ``id_stride``,
            which the driver's id scheme cannot express.

    """
    joints_of = [np.flatnonzero(s.marker_present) for s in group.skeletons]
    total = sum(len(j) for j in joints_of)
    data = MarkerArrayData.new(total)
    if total == 0:
        return data
    for skeleton in group.skeletons:
        if skeleton.id < 0 or skeleton.layout.n_joints > id_stride:
            msg = (
                f"skeleton id {skeleton.id} with {skeleton.layout.n_joints} joints cannot be "
                f"written as driver marker ids (needs id >= 0 and at most {id_stride} joints)"
            )
            raise CodecError(msg)
    body_of = np.repeat([s.id for s in group.skeletons], [len(j) for j in joints_of])
    joints = np.concatenate(joints_of)
    markers = np.concatenate(
        [s.markers[j] for s, j in zip(group.skeletons, joints_of, strict=True)]
    )
    orientations = markers[:, 4:8].copy()
    orientations[~np.isfinite(orientations).all(axis=1)] = 0.0
    levels = np.rint(markers[:, 0] * confidence_levels)
    data.stamps_ns[:] = group.stamp_ns
    data.frame_ids = [group.frame_id] * total
    data.namespaces = [
        "" if s.layout is AZURE_KINECT else s.layout.name
        for s, j in zip(group.skeletons, joints_of, strict=True)
        for _ in range(len(j))
    ]
    data.ids[:] = body_of * id_stride + joints
    data.types[:] = SPHERE
    data.actions[:] = ADD
    data.poses[:, :3] = markers[:, 1:4]
    data.poses[:, 3:7] = orientations
    data.scales[:] = JOINT_SCALE
    data.colors[:] = _PALETTE[body_of % len(_PALETTE)]
    data.lifetimes_ns[:] = lifetime_ns
    data.texts = ["" if math.isnan(v) else str(int(v)) for v in levels.tolist()]
    return data
