"""Biomechanics exports of a stage's output: joint positions (CSV, OpenSim .trc), joint angles.

One file set per person (skeleton id). Times are reference-clock seconds from the first frame.
The .trc follows OpenSim's marker-file layout (tab separated; header with data rate, units m,
marker names; then Frame#, Time and X/Y/Z per marker); OpenSim expects Y up, so positions are
written in the output's world frame rotated by ``up_axis`` when asked.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from hiros_core.layouts import AZURE_KINECT, Layout
from hiros_core.model import SkeletonGroup
from hiros_eval.body import JOINT_ANGLES, joint_angles

__all__ = ["person_series", "write_angles_csv", "write_positions_csv", "write_trc"]


def person_series(groups: Sequence[SkeletonGroup]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Skeleton id -> (times (N,) s, positions (N, J, 3) m, NaN where a joint is absent)."""
    rows: dict[int, list[tuple[int, np.ndarray]]] = defaultdict(list)
    for group in groups:
        for skeleton in group.skeletons:
            positions = np.where(skeleton.marker_present[:, None], skeleton.positions, np.nan)
            rows[skeleton.id].append((skeleton.src_time_ns or group.stamp_ns, positions))
    out = {}
    for person, samples in rows.items():
        samples.sort(key=lambda sample: sample[0])
        times = np.array([t for t, _ in samples], dtype=np.int64)
        out[person] = ((times - times[0]) * 1e-9, np.stack([p for _, p in samples]))
    return out


def write_positions_csv(
    path: Path, times: np.ndarray, positions: np.ndarray, layout: Layout = AZURE_KINECT
) -> None:
    """``time, <Joint>_x, <Joint>_y, <Joint>_z, ...`` in metres."""
    header = ["time"] + [f"{name}_{axis}" for name in layout.joint_names for axis in "xyz"]
    table = np.column_stack([times, positions.reshape(len(times), -1)])
    np.savetxt(path, table, delimiter=",", header=",".join(header), comments="", fmt="%.6f")


def write_angles_csv(
    path: Path, times: np.ndarray, positions: np.ndarray, layout: Layout = AZURE_KINECT
) -> None:
    """``time, knee_left, ...`` in degrees (the angles of ``hiros_eval.body``)."""
    angles = joint_angles(positions, layout)
    table = np.column_stack([times, *(angles[name] for name in JOINT_ANGLES)])
    np.savetxt(
        path,
        table,
        delimiter=",",
        header=",".join(["time", *JOINT_ANGLES]),
        comments="",
        fmt="%.4f",
    )


def write_trc(
    path: Path,
    times: np.ndarray,
    positions: np.ndarray,
    layout: Layout = AZURE_KINECT,
    *,
    z_up_to_y_up: bool = True,
) -> None:
    """An OpenSim marker file; NaN (missing) coordinates are written empty, as OpenSim expects."""
    rate = (
        (len(times) - 1) / (times[-1] - times[0])
        if len(times) > 1 and times[-1] > times[0]
        else 30.0
    )
    points = positions.copy()
    if z_up_to_y_up:  # world z up -> OpenSim y up (x forward kept, right-handed)
        points = np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)
    names = layout.joint_names
    lines = [
        f"PathFileType\t4\t(X/Y/Z)\t{path.name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\tOrigNumFrames",
        f"{rate:.4f}\t{rate:.4f}\t{len(times)}\t{len(names)}\tm\t{rate:.4f}\t1\t{len(times)}",
        "Frame#\tTime\t" + "\t\t\t".join(names) + "\t\t",
        "\t\t" + "\t".join(f"X{i}\tY{i}\tZ{i}" for i in range(1, len(names) + 1)),
        "",
    ]
    for frame, (time, row) in enumerate(zip(times, points, strict=True), start=1):
        values = ["" if not np.isfinite(v) else f"{v:.6f}" for v in row.ravel()]
        lines.append(f"{frame}\t{time:.6f}\t" + "\t".join(values))
    path.write_text("\n".join(lines) + "\n")
