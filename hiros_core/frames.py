"""Static transforms that join each camera's driver TF tree to the world without a second parent.

A body-tracking driver publishes its own static tree under each camera. The Azure Kinect ROS
driver's starts at ``<prefix>camera_base`` and gives ``<prefix>depth_camera_link`` (the frame
of the skeletons) the parent ``<prefix>camera_base``. Publishing ``world -> <prefix>
depth_camera_link`` beside it would give that frame two parents and break tf2 (lookups then
depend on which message arrived last). So each camera is attached at the root of its driver's
tree instead: ``world -> <prefix>camera_base``, the calibrated pose composed with the inverse
of the driver's fixed ``camera_base -> depth_camera_link`` transform, so that the driver's own
edge carries the rest and ``world -> depth_camera_link`` through it is exactly the calibration.

Frames that are not a driver's (no ``depth_camera_link`` suffix) or a mount with no base
frame attach the skeleton frame to the world directly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from hiros_core.calibration import Calibration
from hiros_core.cdr import PlanBuilder
from hiros_core.geometry import RigidTransform

__all__ = [
    "AZURE_KINECT_MOUNT",
    "DIRECT_MOUNT",
    "CameraMount",
    "StaticTransform",
    "camera_transforms",
    "encode_tf_message",
    "recording_transforms",
]


class StaticTransform(NamedTuple):
    """One TF edge: ``p_parent = R p_child + t`` (rotation x, y, z, w; metres)."""

    parent: str
    child: str
    translation: np.ndarray
    rotation: np.ndarray


@dataclass(frozen=True)
class CameraMount:
    """Where a camera's skeleton frame hangs in its driver's TF tree.

    A frame ``<prefix><frame_suffix>`` is the child of ``<prefix><base_suffix>`` through the
    fixed ``base_to_frame`` transform (x, y, z, qx, qy, qz, qw: ``p_base = R p_frame + t``).
    An empty ``base_suffix`` attaches the skeleton frame to the world directly.
    """

    frame_suffix: str = "depth_camera_link"
    base_suffix: str = "camera_base"
    base_to_frame: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)

    def base_of(self, frame_id: str) -> str | None:
        """The driver's root frame above ``frame_id``, or None where there is none."""
        if not self.base_suffix or not frame_id.endswith(self.frame_suffix):
            return None
        return frame_id[: len(frame_id) - len(self.frame_suffix)] + self.base_suffix

    @property
    def fixed(self) -> RigidTransform:
        """The driver's ``base -> frame`` transform."""
        values = np.asarray(self.base_to_frame, dtype=float)
        return RigidTransform.from_quaternion(values[3:], values[:3])


AZURE_KINECT_MOUNT = CameraMount(
    base_to_frame=(0.0, 0.0, 0.0018, -0.52548275, 0.52548275, -0.47314679, 0.47314679)
)
"""The Azure Kinect ROS driver's ``camera_base -> depth_camera_link``: the depth camera 1.8 mm
up in the depth window and tilted 6 degrees down about its x axis, then turned from the
ROS body frame (x forward, z up) into the optical frame (z forward, y down). Source:
microsoft/Azure_Kinect_ROS_Driver, ``src/k4a_calibration_transform_data.cpp``,
``getDepthToBaseTranslationCorrection`` (0, 0, 1.8 mm) and ``getDepthToBaseRotationCorrection``
(``setEuler(-pi/2, pi, pi/2) * setEuler(0, -6 deg, 0)``; tf2's ``setEuler`` takes yaw about
y, pitch about x, roll about z). The depth camera's forward axis is (0.9945, 0, -0.1045) in
``camera_base``: 6 degrees below its x axis."""

DIRECT_MOUNT = CameraMount(base_suffix="")
"""No driver tree: ``world -> <skeleton frame>``."""


def camera_transforms(
    calibration: Calibration, mount: CameraMount = AZURE_KINECT_MOUNT
) -> list[StaticTransform]:
    """``world -> <camera_base>`` (or ``-> <frame>``) for each calibrated camera.

    The reference camera is included like the others (its frame is not the world's),
    unless the world is named after its frame.
    """
    out = []
    for camera in calibration.cameras.values():
        if camera.frame_id == calibration.world_frame:  # a world named after a camera frame
            continue
        pose = camera.extrinsics  # skeleton frame -> world
        base = mount.base_of(camera.frame_id)
        child = camera.frame_id
        if base is not None:
            pose, child = pose @ mount.fixed.inverse(), base
        out.append(
            StaticTransform(calibration.world_frame, child, pose.translation, pose.quaternion)
        )
    return out


def recording_transforms(
    calibration: Calibration, mount: CameraMount = AZURE_KINECT_MOUNT
) -> list[StaticTransform]:
    """The static tree a recording without the driver needs: ours and the driver's fixed edges.

    ``camera_transforms`` plus ``<prefix>camera_base -> <prefix>depth_camera_link`` for each
    camera attached through its base, which the driver would publish live.
    """
    out = camera_transforms(calibration, mount)
    fixed = mount.fixed
    for camera in calibration.cameras.values():
        base = mount.base_of(camera.frame_id)
        if base is not None:
            out.append(StaticTransform(base, camera.frame_id, fixed.translation, fixed.quaternion))
    return out


def encode_tf_message(edges: list[StaticTransform], stamp_ns: int) -> bytes:
    """``tf2_msgs/msg/TFMessage`` (CDR) of ``edges``, each stamped ``stamp_ns``."""
    message = PlanBuilder()
    sec, nanosec = divmod(int(stamp_ns), 1_000_000_000)
    message.u32(len(edges))
    for edge in edges:
        message.i32(sec)
        message.u32(nanosec)
        message.string(edge.parent)
        message.string(edge.child)
        for value in (*edge.translation, *edge.rotation):
            message.f64(float(value))
    return bytes(message.buf)
