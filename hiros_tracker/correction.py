"""Applying the calibration: a camera's skeletons moved into the world frame and reference clock.

The tracker does this itself (rather than each bridge) so that any bridge's raw output can feed
it, and so that a calibration refined live by the ``calib`` node takes effect on the next frame.
DESIGN.md: ``p_world = R p_camera + t`` and
``t_reference = t_camera + time_offset + drift * (t_camera - drift_epoch)``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hiros_core.accounting import Drops
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.geometry import RigidTransform
from hiros_core.model import STATE_WIDTH, Skeleton, SkeletonGroup, SkeletonRows, stack_rows
from hiros_tracker import kernels

__all__ = ["CameraCorrection", "MovedFrame"]

UNCALIBRATED = "uncalibrated camera"
"""Drop reason of a group whose camera has no calibration (a whole frame)."""
MAX_REMEMBERED = 64
"""Frame ids (and cameras without calibration) remembered at most: frame ids come from the
input, and a publisher of ever-new ones must not make a long-running node grow."""


class CameraCorrection:
    """Moves each camera's ``SkeletonGroup`` into the world frame and onto the reference clock.

    Cameras are looked up by name (the topic namespace, ``group.camera``) and, failing that, by
    the calibration's ``frame_id``. A camera with no calibration is remembered in
    ``uncalibrated`` (so a node can report it once) and its groups are dropped, counted in
    ``drops``.

    Attributes:
        world_frame: frame id of the output groups.
        drops: reason -> count, shared with the owning stage (an uncalibrated camera's
            frame is dropped whole).
        uncalibrated: cameras seen without calibration since the last ``set_calibration``
            (the first ``MAX_REMEMBERED``; the frames of all of them are counted).

    """

    def __init__(self, calibration: Calibration | None = None, drops: Drops | None = None) -> None:
        self.drops = drops if drops is not None else Drops()
        self.world_frame = "world"
        self.uncalibrated: set[str] = set()
        self._cameras: dict[str, CameraCalibration] = {}
        self._by_frame: dict[str, str] = {}
        self._transforms: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._names: dict[str, str | None] = {}  # frame id -> camera_name, until a change
        if calibration is not None:
            self.set_calibration(calibration)

    @property
    def cameras(self) -> dict[str, CameraCalibration]:
        """The calibrated cameras by name (read-only view by convention)."""
        return self._cameras

    def set_calibration(self, calibration: Calibration) -> None:
        """Replace the whole calibration (file reloaded, or a new one from ``calib``)."""
        self.world_frame = calibration.world_frame
        self._cameras = {}
        self._by_frame = {}
        self._transforms = {}
        self._names = {}
        for name, camera in calibration.cameras.items():
            self.set_camera(name, camera)

    def set_camera(self, name: str, camera: CameraCalibration) -> None:
        """Replace one camera's calibration (a live parameter update from ``calib``)."""
        self._cameras[name] = camera
        self._transforms[name] = _row_transform(camera.extrinsics)
        if camera.frame_id:
            self._by_frame[camera.frame_id] = name
        self._names = {}
        self.uncalibrated.discard(name)

    def camera_name(self, group: SkeletonGroup) -> str | None:
        """The calibration's name for the camera a group came from, None when uncalibrated.

        Kept per frame id until the calibration changes: every frame asks.
        """
        frame_id = group.frame_id
        if frame_id in self._names:
            return self._names[frame_id]
        name = group.camera
        if name not in self._cameras:
            name = self._by_frame.get(frame_id)
        if len(self._names) >= MAX_REMEMBERED:
            self._names.clear()
        self._names[frame_id] = name
        return name

    def apply(self, group: SkeletonGroup) -> SkeletonGroup | None:
        """The group in the world frame with reference-clock stamps, or None (counted) if unknown.

        Each skeleton keeps its ``src_frame`` (the camera's frame, which the merger needs to
        tell cameras apart); ``src_time`` becomes the corrected stamp. A skeleton without a
        ``src_time`` (0) takes the header stamp.
        """
        moved = self.move(group)
        return None if moved is None else moved.group

    def move(self, group: SkeletonGroup) -> MovedFrame | None:
        """``apply``, keeping the moved rows stacked for a caller working on the whole frame."""
        name = self.camera_name(group)
        if name is None:
            if len(self.uncalibrated) < MAX_REMEMBERED:
                self.uncalibrated.add(group.camera)
            self.drops.frame(UNCALIBRATED)
            return None
        camera = self._cameras[name]
        header_ns = group.stamp_ns
        stamp_ns = camera.to_reference_ns(header_ns)
        times = [
            stamp_ns if source_ns in (0, header_ns) else camera.to_reference_ns(source_ns)
            for source_ns in (skeleton.src_time_ns for skeleton in group.skeletons)
        ]
        skeletons, stack = _moved(group.skeletons, self._transforms[name], times, group.frame_id)
        return MovedFrame(SkeletonGroup(stamp_ns, self.world_frame, skeletons), stack, name)


class MovedFrame(NamedTuple):
    """A camera frame in the world frame and on the reference clock (``CameraCorrection.move``).

    ``stack`` holds its skeletons' rows stacked (they are its row views, in order), or None
    when their layouts differ; ``camera`` is the calibration's name for the camera.
    """

    group: SkeletonGroup
    stack: SkeletonRows | None
    camera: str


def _row_transform(extrinsics: RigidTransform) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """What moves a whole marker/link row: ``R`` ``(3, 3)``, ``t`` ``(3,)`` and ``(4, 4)``.

    ``R`` moves the position (plus ``t``) and each twist and accel vector; the ``(4, 4)``
    matrix is the quaternion product ``q_R ⊗ q`` on the orientation; the confidence stays.
    """
    return (
        np.ascontiguousarray(extrinsics.rotation.as_matrix(), dtype=float),
        np.asarray(extrinsics.translation, dtype=float).copy(),
        _left_product(extrinsics.rotation.as_quat()),
    )


def _moved(
    skeletons: list[Skeleton],
    transform: tuple[np.ndarray, np.ndarray, np.ndarray],
    times_ns: list[int],
    frame_id: str,
) -> tuple[list[Skeleton], SkeletonRows | None]:
    """New skeletons moved by a ``_row_transform``, all rows of a frame at once.

    They are stamped ``times_ns`` (one per skeleton) and keep their ``src_frame``, else take
    ``frame_id``: set here rather than on the finished skeletons (one pass per frame).

    The result equals ``RigidTransform.apply_to_skeleton`` on each skeleton (a test checks it):
    a field with any NaN stays all NaN, quaternions are normalised first. Every row of the
    frame (markers, links and boxes of all people) is moved by one compiled loop
    (``kernels.move_frame``): flat in the number of people, which is what the tracker's time
    budget needs. When the skeletons share a layout, the new ones are the row views of one
    ``SkeletonRows`` of their own (returned; else None): a copy of the input's stack, which
    the bridge and the reader hand over whole (``stack_rows``), so the frame costs a few
    copies whatever its size, and the stages after the tracker get the stack back for free.
    """
    if not skeletons:
        return [], None
    layout = skeletons[0].layout
    if any(skeleton.layout is not layout for skeleton in skeletons):
        return _moved_apart(skeletons, transform, times_ns, frame_id), None
    stack = stack_rows(skeletons)
    if np.may_share_memory(stack.markers, skeletons[0].markers):  # the input's own stack
        stack = SkeletonRows(*kernels.moved_frame(*stack, *transform))
    else:  # new arrays already
        kernels.move_frame(stack.markers, stack.links, stack.bounding_boxes, *transform)
    moved = stack.skeletons(
        [skeleton.id for skeleton in skeletons],
        times_ns,
        [skeleton.src_frame or frame_id for skeleton in skeletons],
        layout,
        [skeleton.confidence for skeleton in skeletons],
        max_sizes=[(skeleton.max_markers, skeleton.max_links) for skeleton in skeletons],
    )
    return moved, stack


def _moved_apart(
    skeletons: list[Skeleton],
    transform: tuple[np.ndarray, np.ndarray, np.ndarray],
    times_ns: list[int],
    frame_id: str,
) -> list[Skeleton]:
    """``_moved`` for skeletons of different layouts: every row in one array, split back."""
    boxes = np.array([s.bounding_box for s in skeletons])
    parts = [part for s in skeletons for part in (s.markers, s.links)]
    rows = np.concatenate(parts)
    kernels.move_frame(rows[None], np.empty((1, 0, STATE_WIDTH)), boxes, *transform)
    pieces = np.split(rows, np.cumsum([len(part) for part in parts])[:-1])
    return [
        Skeleton(
            skeleton.id,
            times_ns[d],
            skeleton.src_frame or frame_id,
            skeleton.layout,
            pieces[2 * d],
            pieces[2 * d + 1],
            skeleton.marker_present.copy(),
            skeleton.link_present.copy(),
            skeleton.confidence,
            boxes[d],
            skeleton.max_markers,
            skeleton.max_links,
        )
        for d, skeleton in enumerate(skeletons)
    ]


def _left_product(rotation: np.ndarray) -> np.ndarray:
    """``(4, 4)`` matrix of the Hamilton product ``rotation ⊗ q`` on quaternions x, y, z, w."""
    x, y, z, w = rotation
    return np.array([[w, -z, y, x], [z, w, -x, y], [-y, x, w, z], [-x, -y, -z, w]])
