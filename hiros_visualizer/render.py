"""A picture of what RViz or Foxglove shows for a recording: its markers at one moment, drawn.

Reads a marker topic of a recording (``hiros run``'s ``/hiros/filter/markers`` by default) and
the cameras of its ``/hiros/calibration``, and draws, in the world frame, what a 3D panel
would: each person's joints (sphere lists), limbs (line lists), labels and arrows, the cameras
as their viewing direction, and a 1 m floor grid at z = 0. For the README and reports::

    python -m hiros_visualizer.render out.mcap --at 2.0 --out view.png
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import yaml

from hiros_core.calibration import Calibration
from hiros_core.codec import MarkerArrayData, decode_marker_array
from hiros_core.recording import RecordingReader
from hiros_visualizer.overlays import ARROW, DELETE, DELETEALL

__all__ = ["markers_at", "render"]

SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING = 7, 5, 9


def markers_at(
    path: str | Path, topic: str, seconds: float
) -> tuple[list[MarkerArrayData], Calibration | None]:
    """The markers alive ``seconds`` after the recording's first message, and its calibration.

    Replays the topic's ADD, DELETE and DELETEALL in order up to that time, as a viewer does
    (lifetimes aside), keeping the last message of each ``(namespace, id)``.
    """
    alive: dict[tuple[str, int], tuple[MarkerArrayData, int]] = {}
    calibration = None
    with RecordingReader(path) as reader:
        start = None
        for message in reader.messages({topic, "/hiros/calibration"} & set(reader.topics)):
            start = message.log_time_ns if start is None else start
            if message.topic == "/hiros/calibration":
                text = bytes(message.data[8:]).split(b"\x00", 1)[0].decode()
                calibration = Calibration.from_dict(yaml.safe_load(text), f"{path}")
                continue
            if message.log_time_ns - start > seconds * 1e9:
                break
            data = decode_marker_array(message.data)
            for i in range(len(data)):
                key = (data.namespaces[i], int(data.ids[i]))
                if data.actions[i] == DELETEALL:
                    alive.clear()
                elif data.actions[i] == DELETE:
                    alive.pop(key, None)
                else:
                    alive[key] = (data, i)
    return [_one(data, i) for data, i in alive.values()], calibration


def _one(data: MarkerArrayData, i: int) -> MarkerArrayData:
    out = MarkerArrayData.new(1, frame_id=data.frame_ids[i])
    out.types[0], out.colors[0], out.poses[0] = data.types[i], data.colors[i], data.poses[i]
    out.points, out.texts = [data.points[i]], [data.texts[i]]
    return out


def render(
    markers: list[MarkerArrayData], calibration: Calibration | None, out: str | Path
) -> Path:
    """Draw the markers (and cameras) into a PNG at ``out``; returns its path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(9, 6))
    ax = fig.add_subplot(projection="3d")
    points = [np.zeros((1, 3))]
    for marker in markers:
        kind, color, drawn = int(marker.types[0]), marker.colors[0], marker.points[0]
        if kind == SPHERE_LIST:
            ax.scatter(*drawn.T, color=color, s=12, depthshade=False)
        elif kind in (LINE_LIST, ARROW):
            for a, b in drawn.reshape(-1, 2, 3):
                ax.plot(*np.stack([a, b]).T, color=color, linewidth=2)
        elif kind == TEXT_VIEW_FACING:
            ax.text(*marker.poses[0, :3], marker.texts[0], color="black", fontsize=8)
        points.append(drawn.reshape(-1, 3))
    for name, camera in (calibration.cameras if calibration else {}).items():
        where, forward = camera.translation, camera.extrinsics.rotate([0.0, 0.0, 0.6])
        ax.quiver(*where, *forward, color="dimgray", linewidth=1.5)
        ax.text(*where, name, color="dimgray", fontsize=8)
        points.append(where[None])
    every = np.concatenate(points)
    low, high = every.min(axis=0), every.max(axis=0)
    grid = np.arange(np.floor(low[0]), np.ceil(high[0]) + 1)
    rows = np.arange(np.floor(low[1]), np.ceil(high[1]) + 1)
    for x in grid:
        ax.plot([x, x], [rows[0], rows[-1]], [0, 0], color="lightgray", linewidth=0.6)
    for y in rows:
        ax.plot([grid[0], grid[-1]], [y, y], [0, 0], color="lightgray", linewidth=0.6)
    top = max(float(high[2]), 2.0)
    ax.set_xlim(grid[0], grid[-1])
    ax.set_ylim(rows[0], rows[-1])
    ax.set_zlim(0.0, top)
    ax.set_box_aspect((grid[-1] - grid[0], rows[-1] - rows[0], top))  # metres alike
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    ax.view_init(elev=28, azim=-70)
    fig.tight_layout()
    out = Path(out)
    fig.savefig(out, dpi=100, bbox_inches="tight")
    plt.close(fig)
    return out


def main(argv: list[str] | None = None) -> None:
    """``python -m hiros_visualizer.render REC --at SECONDS --out PNG``."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("recording")
    parser.add_argument("--topic", default="/hiros/filter/markers")
    parser.add_argument("--at", type=float, default=1.0, help="seconds after the first message")
    parser.add_argument("--out", default="view.png")
    args = parser.parse_args(argv)
    markers, calibration = markers_at(args.recording, args.topic, args.at)
    print(render(markers, calibration, args.out))


if __name__ == "__main__":
    main()
