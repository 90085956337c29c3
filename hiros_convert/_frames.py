"""Rows of detections -> per-camera SkeletonGroup lists, shared by every file parser.

A parser reduces its format to arrays with one row per detection (one person seen by one
camera at one instant): stamps, body ids and ``(N, J, 3)`` positions. This module groups the
rows of one camera into one SkeletonGroup per stamp, in time order, so every format ends in
the same model and the same drop reasons.
"""

from __future__ import annotations

import itertools
import re
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hiros_core.errors import RecordingError
from hiros_core.layouts import Layout
from hiros_core.model import Skeleton, SkeletonGroup

__all__ = ["CameraStream", "build_stream", "camera_frame", "camera_topics", "topic_name"]

_NOT_NAME = re.compile(r"[^A-Za-z0-9_]+")


def topic_name(raw: str) -> str:
    """Make a camera name usable as a ROS namespace: ``138.251.207.136`` -> ``kinect_138_...``.

    ROS names hold letters, digits and underscores and cannot start with a digit, so other
    characters become underscores and a leading digit gets the ``kinect_`` prefix.
    """
    name = _NOT_NAME.sub("_", raw.strip()).strip("_")
    if not name:
        return "camera"
    return f"kinect_{name}" if name[0].isdigit() else name


def camera_topics(raws: Iterable[str], path: str | Path) -> dict[str, str]:
    """``{camera name in the file: topic namespace}``, refusing names that would share one.

    ``cam-A`` and ``cam_A`` both become ``cam_A``: converted as they were, the second
    camera's frames replaced the first's without a word.

    Raises:
        RecordingError: naming the file and the colliding camera names.

    """
    topics: dict[str, str] = {}
    for raw in dict.fromkeys(raws):
        name = topic_name(raw)
        clash = [other for other, taken in topics.items() if taken == name]
        if clash:
            msg = (
                f"{path}: cameras {clash[0]!r} and {raw!r} both become the topic namespace "
                f"{name!r}; rename one of them in the camera column"
            )
            raise RecordingError(msg)
        topics[raw] = name
    return topics


def camera_frame(camera: str) -> str:
    """Return the driver's depth frame of a camera (DESIGN.md: ``<cam>_depth_camera_link``)."""
    return f"{camera}_depth_camera_link"


@dataclass
class CameraStream:
    """One camera's groups and when a recorder would have received each.

    Attributes:
        groups: SkeletonGroups in camera-clock order.
        receive_ns: ``(G,)`` int64 log times for a recording (the recorder's clock where the
            file has one, else the camera stamps).

    """

    groups: list[SkeletonGroup]
    receive_ns: np.ndarray


def build_stream(
    camera: str,
    stamps_ns: np.ndarray,
    body_ids: np.ndarray,
    positions: np.ndarray,
    layout: Layout,
    *,
    orientations: np.ndarray | None = None,
    confidences: np.ndarray | None = None,
    receive_ns: np.ndarray | None = None,
    drops: Counter[str] | None = None,
) -> CameraStream:
    """One SkeletonGroup per distinct stamp of one camera, in time order.

    Args:
        camera: camera name; the frame is ``<camera>_depth_camera_link``.
        stamps_ns: ``(N,)`` int64 camera-clock stamps of the detections.
        body_ids: ``(N,)`` body (person) ids.
        positions: ``(N, J, 3)`` metres, NaN where a joint is absent.
        layout: the joints of ``J``.
        orientations: ``(N, J, 4)`` quaternions x, y, z, w, or None.
        confidences: ``(N, J)`` joint confidences, or None.
        receive_ns: ``(N,)`` recorder-clock time of each row; a group's is its earliest row's,
            raised where needed so that log times follow the camera's stamps. Default: the
            stamps.
        drops: counts rows dropped: ``repeated_detection`` (same stamp and body twice: the
            recorder sampled one camera frame twice; the first copy is kept),
            ``no_joints`` (a detection whose joints are all absent).

    Returns:
        The stream; skeletons sorted by body id; a stamp whose detections were all dropped
        gives no group.

    """
    drops = drops if drops is not None else Counter()
    stamps_ns = np.asarray(stamps_ns, dtype=np.int64)
    body_ids = np.asarray(body_ids, dtype=np.int64)
    order = np.lexsort((body_ids, stamps_ns))
    stamps_ns, body_ids = stamps_ns[order], body_ids[order]
    repeated = np.zeros(len(order), dtype=bool)
    repeated[1:] = (stamps_ns[1:] == stamps_ns[:-1]) & (body_ids[1:] == body_ids[:-1])
    empty = ~np.isfinite(positions[order]).all(axis=2).any(axis=1)
    drops["repeated_detection"] += int(repeated.sum())
    drops["no_joints"] += int((empty & ~repeated).sum())
    keep = ~repeated & ~empty
    frame = camera_frame(camera)
    rows, kept_stamps, kept_ids = order[keep], stamps_ns[keep], body_ids[keep]
    starts = np.flatnonzero(np.r_[True, kept_stamps[1:] != kept_stamps[:-1]])
    bounds = [*starts.tolist(), len(rows)] if len(rows) else [0]
    receive = stamps_ns if receive_ns is None else np.asarray(receive_ns, dtype=np.int64)[order]
    group_receive = (
        np.minimum.reduceat(receive[keep], starts) if len(rows) else np.empty(0, np.int64)
    )
    # A camera delivers its frames in order: a frame logged before an older one was seen
    # late by the recorder, so its log time moves up to keep each camera's topic in order.
    group_receive = np.maximum.accumulate(group_receive) if len(rows) else group_receive
    groups: list[SkeletonGroup] = []
    for begin, end in itertools.pairwise(bounds):
        stamp = int(kept_stamps[begin])
        skeletons = [
            Skeleton.from_positions(
                positions[row],
                layout,
                skeleton_id=int(body_id),
                src_time_ns=stamp,
                src_frame=frame,
                confidences=None if confidences is None else confidences[row],
                orientations=None if orientations is None else orientations[row],
            )
            for row, body_id in zip(rows[begin:end], kept_ids[begin:end], strict=True)
        ]
        groups.append(SkeletonGroup(stamp, frame, skeletons))
    return CameraStream(groups, group_receive)
