"""The generic skeleton CSV: one row per joint of one person seen by one camera.

Any tracker's output can be brought in by writing this format (a header row is required;
columns in any order; extra columns ignored)::

    camera,stamp_ns,body_id,joint,x,y,z,qx,qy,qz,qw,confidence
    k01,1635261007408000000,1,Pelvis,0.320,-0.793,3.235,0,0,0,1,1.0
    k01,1635261007408000000,1,SpineNaval,0.325,-0.951,3.148,,,,,

* ``camera``: camera name (becomes the topic namespace and ``<camera>_depth_camera_link``);
  optional, default ``k01``.
* ``stamp_ns`` (integer nanoseconds) or ``stamp`` (float seconds): the camera's clock.
* ``body_id``: integer person id within the camera.
* ``joint``: a joint name of the layout (``--layout``, default ``azure_kinect``) or its index.
* ``x, y, z``: metres in the camera frame (x right, y down, z forward for Azure Kinect).
* ``qx, qy, qz, qw`` (optional): joint orientation; ``confidence`` (optional): 0..1.

Empty cells or ``NA`` mean unknown. Rows of the same camera, stamp and body form one skeleton.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from hiros_convert._frames import CameraStream, build_stream, camera_topics
from hiros_convert._table import Table, read_table
from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.model import SkeletonGroup

__all__ = ["read_generic_csv", "read_generic_streams"]


def _joint_indices(names: np.ndarray, layout: Layout) -> np.ndarray:
    """Layout index of each joint cell (a name or a number), -1 when unknown."""
    unique, inverse = np.unique(np.char.strip(names), return_inverse=True)
    lookup = {name: i for i, name in enumerate(layout.joint_names)}
    indices = np.array(
        [
            lookup.get(name, int(name) if name.isdigit() and int(name) < layout.n_joints else -1)
            for name in unique.tolist()
        ],
        dtype=np.int64,
    )
    return indices[inverse] if len(unique) else np.empty(0, np.int64)


_MAX_SECONDS = 9.2e9
"""Stamps in seconds must be below this: int64 nanoseconds end at 9.22e18."""


def _drop_unreadable_rows(
    table: Table, integer_cols: list[int], number_cols: list[int], drops: Counter[str]
) -> None:
    """Drop (counted ``bad_row``) the rows whose integer or number cells do not parse.

    One garbled row in a long take costs that row, not the whole conversion.
    """
    good = np.ones(len(table.rows), dtype=bool)
    for column in integer_cols:
        good &= table.readable(column, integer=True)
    for column in number_cols:
        good &= table.readable(column)
    table.keep(good, drops)


def _stamps_ns(
    table: Table, stamp_col: int | None, seconds_col: int | None, drops: Counter[str]
) -> np.ndarray:
    """Each row's stamp in ns (from ``stamp_ns``, else seconds); rows with none usable go.

    Negative, non-finite or too large stamps are counted ``bad_row``: a recording's times
    are 0 to 2^63 ns.
    """
    if stamp_col is not None:
        stamps_ns = table.integers(stamp_col)
    else:
        seconds = table.numbers([seconds_col])[:, 0]
        good = np.isfinite(seconds) & (seconds >= 0) & (seconds < _MAX_SECONDS)
        table.keep(good, drops)
        stamps_ns = np.rint(seconds[good] * 1e9).astype(np.int64)
    table.keep(stamps_ns >= 0, drops)
    return stamps_ns[stamps_ns >= 0]


def read_generic_streams(
    path: str | Path, *, layout: Layout = AZURE_KINECT, drops: Counter[str] | None = None
) -> dict[str, CameraStream]:
    """Per-camera streams of a generic skeleton CSV; see ``read_generic_csv``."""
    drops = drops if drops is not None else Counter()
    table = read_table(path, drops)
    body_col = table.require("body id", "body_id", "body", "person_id", "id")
    joint_col = table.require("joint", "joint", "joint_name")
    xyz = [table.require(axis, axis) for axis in "xyz"]
    stamp_col = table.find("stamp_ns")
    seconds_col = (
        table.require("stamp (stamp_ns or stamp)", "stamp", "time") if stamp_col is None else None
    )
    quaternion = [table.find(q) for q in ("qx", "qy", "qz", "qw")]
    value_cols = [*xyz, *quaternion, table.find("confidence")]
    integer_cols = [c for c in (stamp_col, body_col) if c is not None]
    number_cols = [c for c in (seconds_col, *value_cols) if c is not None]
    _drop_unreadable_rows(table, integer_cols, number_cols, drops)
    stamps_ns = _stamps_ns(table, stamp_col, seconds_col, drops)
    camera_col = table.find("camera", "camera_id")
    cameras = (
        np.char.strip(table.rows[:, camera_col])
        if camera_col is not None
        else np.full(len(table.rows), "k01")
    )
    body_ids = table.integers(body_col)
    joints = _joint_indices(table.rows[:, joint_col], layout)
    known = joints >= 0
    drops["unknown_joint"] += int((~known).sum())
    values = table.numbers(value_cols)
    out: dict[str, CameraStream] = {}
    for raw, camera in camera_topics(cameras.tolist(), table.path).items():
        rows = np.flatnonzero((cameras == raw) & known)
        keys = np.stack([stamps_ns[rows], body_ids[rows]], axis=1)
        detections, which = np.unique(keys, axis=0, return_inverse=True)
        which = which.reshape(-1)
        shape = (len(detections), layout.n_joints)
        positions = np.full((*shape, 3), np.nan)
        orientations = np.full((*shape, 4), np.nan)
        confidences = np.full(shape, np.nan)
        seen = np.zeros(shape, dtype=bool)
        cells = (which, joints[rows])
        flat = np.ravel_multi_index(cells, shape) if len(rows) else np.empty(0, np.int64)
        _, first = np.unique(flat, return_index=True)
        drops["duplicate_joint"] += len(rows) - len(first)
        rows, cells = rows[first], (which[first], joints[rows][first])
        seen[cells] = True
        positions[cells] = values[rows, 0:3]
        orientations[cells] = values[rows, 3:7]
        confidences[cells] = values[rows, 7]
        out[camera] = build_stream(
            camera,
            detections[:, 0],
            detections[:, 1],
            positions,
            layout,
            orientations=orientations,
            confidences=confidences,
            drops=drops,
        )
    return out


def read_generic_csv(
    path: str | Path, *, layout: Layout = AZURE_KINECT, drops: Counter[str] | None = None
) -> dict[str, list[SkeletonGroup]]:
    """Per-camera SkeletonGroups of a generic skeleton CSV (format in the module docstring).

    Args:
        path: the CSV file.
        layout: the skeleton layout the joint names and indices refer to.
        drops: optional counter: ``bad_row``, ``unknown_joint``, ``duplicate_joint`` (a joint
            given twice for one skeleton: the first row is kept), ``no_joints``.

    Raises:
        RecordingError: the file cannot be read or lacks a required column.

    """
    streams = read_generic_streams(path, layout=layout, drops=drops)
    return {name: s.groups for name, s in streams.items()}
