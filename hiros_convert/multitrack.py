"""KinectMultiTrack CSV (two Kinect v2 cameras, chijuiwu/KinectMultiTrack) -> SkeletonGroups.

One file holds the detections of every camera, one row per (server instant, person, camera):
``Tracker_Time`` (server clock: milliseconds since 0001-01-01, .NET ``DateTime`` ticks / 10^4),
``Person_Id`` or ``Person#`` (the recorder's own association of people across cameras),
``Skeleton_Time`` (the camera's device clock in 100 ns ticks), ``Kinect_Id`` or ``Kinect#``
(the camera's IP address), then 25 joints as ``<Joint>_X/_Y/_Z`` in metres. Missing values are
``NA``.

Each camera becomes one stream named after its IP (``138.251.207.136`` ->
``kinect_138_251_207_136``) whose stamps are the device clock, untouched, so the clocks stay
independent as they were recorded. The server sampled the cameras faster than they produced
frames, so a camera frame often appears on several rows: the copies are dropped
(``repeated_detection``) and each camera frame appears once, in device-clock order. The server
time of a frame's first row, as Unix time, is when a recorder received it.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from hiros_convert._frames import CameraStream, build_stream, camera_topics
from hiros_convert._table import read_table
from hiros_core.errors import RecordingError
from hiros_core.layouts import KINECT_V2
from hiros_core.model import SkeletonGroup

__all__ = ["TICK_NS", "read_multitrack_csv", "read_multitrack_streams"]

TICK_NS = 100
"""Kinect v2 device clock tick (``Skeleton_Time`` unit) in nanoseconds."""
_DOTNET_UNIX_EPOCH_MS = 62_135_596_800_000
"""1970-01-01 in milliseconds since 0001-01-01 (the server's ``Tracker_Time`` origin)."""


def read_multitrack_streams(
    path: str | Path, drops: Counter[str] | None = None
) -> dict[str, CameraStream]:
    """Per-camera streams of a KinectMultiTrack CSV, with server receive times.

    See ``read_multitrack_csv``; ``receive_ns`` is the server's ``Tracker_Time`` as Unix ns
    (the device stamps when the column is missing).
    """
    drops = drops if drops is not None else Counter()
    table = read_table(path, drops)
    camera_col = table.require("camera (Kinect_Id)", "Kinect_Id", "Kinect#", "Kinect")
    person_col = table.require("person (Person_Id)", "Person_Id", "Person#", "Person")
    time_col = table.require("device time (Skeleton_Time)", "Skeleton_Time", "SkeletonTime")
    server_col = table.find("Tracker_Time", "TrackerTime")
    columns = [
        table.find(f"{joint}_{axis}") for joint in KINECT_V2.joint_names for axis in ("X", "Y", "Z")
    ]
    if all(c is None for c in columns):
        msg = f"{table.path}: no Kinect v2 joint columns such as SpineBase_X"
        raise RecordingError(msg)
    positions = table.numbers(columns).reshape(len(table.rows), KINECT_V2.n_joints, 3)
    stamps_ns = table.integers(time_col) * TICK_NS
    receive_ns = None
    if server_col is not None:
        receive_ns = (table.integers(server_col) - _DOTNET_UNIX_EPOCH_MS) * 1_000_000
    person_ids = table.integers(person_col)
    cameras = np.char.strip(table.rows[:, camera_col])
    out: dict[str, CameraStream] = {}
    for raw, camera in camera_topics(cameras.tolist(), table.path).items():
        rows = cameras == raw
        out[camera] = build_stream(
            camera,
            stamps_ns[rows],
            person_ids[rows],
            positions[rows],
            KINECT_V2,
            receive_ns=None if receive_ns is None else receive_ns[rows],
            drops=drops,
        )
    return out


def read_multitrack_csv(
    path: str | Path, drops: Counter[str] | None = None
) -> dict[str, list[SkeletonGroup]]:
    """Per-camera SkeletonGroups of a KinectMultiTrack CSV file.

    Args:
        path: the CSV file.
        drops: optional counter of rows dropped, by reason (``bad_row``,
            ``repeated_detection``, ``no_joints``).

    Returns:
        ``{camera: groups}`` with groups in device-clock order; stamps are ``Skeleton_Time``
        × 100 ns; skeleton ids are the recorder's person ids; KINECT_V2 layout, no
        orientations or confidences (the file has none).

    Raises:
        RecordingError: the file cannot be read or lacks the camera, person, time or joint
            columns.

    """
    return {name: s.groups for name, s in read_multitrack_streams(path, drops).items()}
