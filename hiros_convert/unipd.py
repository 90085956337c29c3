"""UNIPD-BPE Azure Kinect CSV pairs (``<take>KinectPos.csv`` + ``<take>KinectQuat.csv``).

The dataset's reader exports one camera's body tracking as two CSV files with the same rows:
``time`` (Unix time, milliseconds), then for each of the 32 k4abt joints in SDK order
``<Joint>PosX/Y/Z`` (metres, camera depth frame) or ``<Joint>QuatX/Y/Z/W``. One person per
row; the files carry no body id (1, the SDK's first id, is used) and no confidence. Frames in
which nobody was tracked are written as rows of zeros (time 0 included): they are dropped
(``untracked_frame``), and so is any joint at exactly (0, 0, 0), the camera's own origin.
"""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from hiros_convert._frames import CameraStream, build_stream
from hiros_convert._table import read_table
from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import SkeletonGroup

__all__ = ["quat_file_of", "read_unipd_csv", "read_unipd_streams"]


def quat_file_of(pos_path: Path) -> Path | None:
    """The orientation file beside a position file (``...Pos.csv`` -> ``...Quat.csv``)."""
    if "Pos" not in pos_path.stem:
        return None
    head, _, tail = pos_path.stem.rpartition("Pos")
    candidate = pos_path.with_name(f"{head}Quat{tail}{pos_path.suffix}")
    return candidate if candidate.is_file() else None


def read_unipd_streams(
    pos_path: str | Path,
    quat_path: str | Path | None = None,
    *,
    camera: str = "k01",
    body_id: int = 1,
    drops: Counter[str] | None = None,
) -> dict[str, CameraStream]:
    """The camera stream of a UNIPD-BPE Kinect CSV pair; see ``read_unipd_csv``."""
    drops = drops if drops is not None else Counter()
    pos_path = Path(pos_path)
    table = read_table(pos_path, drops)
    time_col = table.require("time", "time", "Time")
    columns = [
        table.find(f"{joint}Pos{axis}") for joint in AZURE_KINECT.joint_names for axis in "XYZ"
    ]
    if all(c is None for c in columns):
        msg = f"{pos_path}: no Azure Kinect position columns such as PelvisPosX"
        raise RecordingError(msg)
    n = len(table.rows)
    positions = table.numbers(columns).reshape(n, AZURE_KINECT.n_joints, 3)
    times_ms = table.integers(time_col)
    positions[(positions == 0.0).all(axis=2)] = np.nan
    tracked = (times_ms != 0) & np.isfinite(positions).any(axis=(1, 2))
    drops["untracked_frame"] += int((~tracked).sum())
    positions, times_ms, n = positions[tracked], times_ms[tracked], int(tracked.sum())
    orientations = None
    quat_path = Path(quat_path) if quat_path is not None else quat_file_of(pos_path)
    if quat_path is not None:
        orientations = _orientations(quat_path, times_ms, drops)
    stream = build_stream(
        camera,
        times_ms * 1_000_000,
        np.full(n, body_id),
        positions,
        AZURE_KINECT,
        orientations=orientations,
        drops=drops,
    )
    return {camera: stream}


def _orientations(path: Path, times_ms: np.ndarray, drops: Counter[str]) -> np.ndarray:
    """``(N, 32, 4)`` x, y, z, w matched to the position rows by time; NaN where missing."""
    table = read_table(path, drops)
    time_col = table.require("time", "time", "Time")
    columns = [
        table.find(f"{joint}Quat{axis}") for joint in AZURE_KINECT.joint_names for axis in "XYZW"
    ]
    quats = table.numbers(columns).reshape(len(table.rows), AZURE_KINECT.n_joints, 4)
    quat_times = table.integers(time_col)
    order = np.argsort(quat_times, kind="stable")
    where = np.searchsorted(quat_times[order], times_ms)
    where = np.minimum(where, len(order) - 1) if len(order) else where
    found = quat_times[order][where] == times_ms if len(order) else np.zeros(len(times_ms), bool)
    drops["no_orientation"] += int((~found).sum())
    out = np.full((len(times_ms), AZURE_KINECT.n_joints, 4), np.nan)
    out[found] = quats[order][where[found]]
    return out


def read_unipd_csv(
    pos_path: str | Path,
    quat_path: str | Path | None = None,
    *,
    camera: str = "k01",
    body_id: int = 1,
    drops: Counter[str] | None = None,
) -> dict[str, list[SkeletonGroup]]:
    """SkeletonGroups of a UNIPD-BPE ``...KinectPos.csv`` (and its ``...KinectQuat.csv``).

    Args:
        pos_path: the positions file.
        quat_path: the orientations file; default: the ``Quat`` file beside ``pos_path`` if
            there is one.
        camera: camera name (the dataset's cameras are ``k01``..``k04``).
        body_id: skeleton id to give the one person.
        drops: optional counter: ``bad_row``, ``untracked_frame`` (a row of zeros),
            ``no_orientation`` (a position row without an orientation row of the same time).

    Returns:
        ``{camera: groups}``; stamps are the ``time`` column in ns; AZURE_KINECT layout.

    Raises:
        RecordingError: a file cannot be read or lacks the time or joint columns.

    """
    streams = read_unipd_streams(pos_path, quat_path, camera=camera, body_id=body_id, drops=drops)
    return {name: s.groups for name, s in streams.items()}
