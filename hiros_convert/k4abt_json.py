"""Azure Kinect Body Tracking SDK offline processor JSON -> SkeletonGroups.

The SDK's ``offline_processor`` sample writes one JSON file per recording::

    {"frames": [{"timestamp_usec": 66666, "num_bodies": 1,
                 "bodies": [{"body_id": 1,
                             "joint_positions": [[x, y, z], ...],      # 32 joints, millimetres
                             "joint_orientations": [[w, x, y, z], ...]}]}],
     "joint_names": [...], "bone_list": [...], "start_offset_usec": 0}

``timestamp_usec`` is the device clock of the depth frame; it becomes the stamp unchanged.
Positions are converted to metres and orientations to x, y, z, w. A per-body
``joint_confidence_levels`` (or ``joint_confidences``) list of k4abt levels 0-3, written by
some forks, becomes confidences level / 3.
"""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from hiros_convert._frames import CameraStream, build_stream
from hiros_core.errors import RecordingError
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import SkeletonGroup

__all__ = ["read_k4abt_json", "read_k4abt_streams"]

_J = AZURE_KINECT.n_joints
_LEVEL_KEYS = ("joint_confidence_levels", "joint_confidences")


MAX_JSON_BYTES = 256 << 20
"""Largest JSON file read (about half an hour of two people at 30 Hz); Python's JSON objects
take about ten times the file's size."""
_MAX_STAMP_USEC = (1 << 63) // 1000 - 1
"""Stamps in nanoseconds are int64: microsecond stamps above this cannot be converted."""
_MAX_BODY_ID = (1 << 31) - 1
"""Skeleton ids are int32 in the messages."""


def _load(path: Path) -> list[Any]:
    try:
        if path.stat().st_size > MAX_JSON_BYTES:
            msg = f"k4abt JSON file {path} is larger than {MAX_JSON_BYTES} bytes: not read"
            raise RecordingError(msg)
        document = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as exc:
        msg = f"cannot read k4abt JSON file {path}: {exc}"
        raise RecordingError(msg) from exc
    except json.JSONDecodeError as exc:
        msg = f"{path} is not valid JSON (line {exc.lineno}: {exc.msg}); is the file complete?"
        raise RecordingError(msg) from exc
    except RecursionError:
        msg = f"{path} nests too deep to be an Azure Kinect offline processor file"
        raise RecordingError(msg) from None
    frames = document.get("frames") if isinstance(document, dict) else None
    if not isinstance(frames, list):
        msg = f"{path} has no 'frames' list: not an Azure Kinect offline processor file"
        raise RecordingError(msg)
    return frames


def _body_arrays(body: Any) -> tuple[int, np.ndarray, np.ndarray, np.ndarray] | None:
    """(id, positions m, orientations xyzw, confidences) of one body, None when malformed."""
    try:
        body_id = int(body["body_id"])
        if not 0 <= body_id <= _MAX_BODY_ID:
            return None
        positions = np.asarray(body["joint_positions"], dtype=float) / 1000.0
        wxyz = np.asarray(body.get("joint_orientations", np.full((_J, 4), np.nan)), dtype=float)
        levels = next((body[k] for k in _LEVEL_KEYS if k in body), None)
        confidences = (
            np.full(_J, np.nan) if levels is None else np.asarray(levels, dtype=float) / 3.0
        )
    except (KeyError, TypeError, ValueError, OverflowError):  # Overflow: an id of 1e400
        return None
    if positions.shape != (_J, 3) or wxyz.shape != (_J, 4) or confidences.shape != (_J,):
        return None
    return body_id, positions, wxyz[:, [1, 2, 3, 0]], confidences


def read_k4abt_streams(
    path: str | Path, *, camera: str = "k01", drops: Counter[str] | None = None
) -> dict[str, CameraStream]:
    """The camera stream of an offline processor JSON file; see ``read_k4abt_json``."""
    drops = drops if drops is not None else Counter()
    path = Path(path)
    stamps, ids, positions, orientations, confidences = [], [], [], [], []
    for frame in _load(path):
        try:
            stamp_usec = int(frame["timestamp_usec"])  # 1e400 is inf: OverflowError
            bodies = list(frame.get("bodies") or [])
        except (KeyError, TypeError, ValueError, OverflowError, AttributeError):
            drops["bad_frame"] += 1
            continue
        if not 0 <= stamp_usec <= _MAX_STAMP_USEC:
            drops["bad_frame"] += 1
            continue
        stamp_ns = stamp_usec * 1000
        for body in bodies:
            arrays = _body_arrays(body)
            if arrays is None:
                drops["bad_body"] += 1
                continue
            stamps.append(stamp_ns)
            ids.append(arrays[0])
            positions.append(arrays[1])
            orientations.append(arrays[2])
            confidences.append(arrays[3])
    if not stamps:
        return {camera: CameraStream([], np.empty(0, np.int64))}
    stream = build_stream(
        camera,
        np.array(stamps),
        np.array(ids),
        np.stack(positions),
        AZURE_KINECT,
        orientations=np.stack(orientations),
        confidences=np.stack(confidences),
        drops=drops,
    )
    return {camera: stream}


def read_k4abt_json(
    path: str | Path, *, camera: str = "k01", drops: Counter[str] | None = None
) -> dict[str, list[SkeletonGroup]]:
    """SkeletonGroups of an Azure Kinect Body Tracking offline processor JSON file.

    Args:
        path: the JSON file.
        camera: camera name for the frame id ``<camera>_depth_camera_link``.
        drops: optional counter: ``bad_frame`` (no timestamp, or one outside 0 to 2^63 ns),
            ``bad_body`` (missing id, an id outside 0 to 2^31 - 1, wrong array sizes),
            ``repeated_detection``, ``no_joints``.

    Returns:
        ``{camera: groups}``, one group per frame with bodies (frames without bodies give no
        group: the file does not say whether the tracker ran).

    Raises:
        RecordingError: the file cannot be read, is not JSON, or has no ``frames`` list.

    """
    return {
        name: s.groups for name, s in read_k4abt_streams(path, camera=camera, drops=drops).items()
    }
