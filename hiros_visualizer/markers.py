"""Skeletons as RViz/Foxglove markers: per person a sphere list, a line list and a label.

Colours come from the skeleton id, so a person keeps their colour from stage to stage and
across frames. Markers carry a short lifetime: a person who leaves disappears by themselves.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass

import numpy as np

from hiros_core.codec import MarkerArrayData
from hiros_core.model import SkeletonGroup

__all__ = ["VisualizerParams", "id_color", "skeleton_markers"]

SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING = 7, 5, 9


@dataclass
class VisualizerParams:
    """How skeletons are drawn."""

    joint_size: float = 0.05
    link_width: float = 0.02
    label_height: float = 0.12
    lifetime: float = 0.25


def id_color(skeleton_id: int) -> np.ndarray:
    """A distinct, stable RGBA colour per id (golden-ratio hue steps)."""
    hue = (skeleton_id * 0.618033988749895) % 1.0
    return np.array([*colorsys.hsv_to_rgb(hue, 0.75, 0.95), 1.0], dtype=np.float32)


def skeleton_markers(
    group: SkeletonGroup, namespace: str = "", params: VisualizerParams | None = None
) -> MarkerArrayData:
    """Three markers per skeleton (ids ``3*i``, ``3*i+1``, ``3*i+2`` by skeleton id)."""
    params = params or VisualizerParams()
    n = 3 * len(group.skeletons)
    data = MarkerArrayData.new(n, frame_id=group.frame_id, stamp_ns=group.stamp_ns)
    data.namespaces = [namespace] * n
    data.lifetimes_ns[:] = round(params.lifetime * 1e9)
    data.points, data.texts = [], []
    for index, skeleton in enumerate(group.skeletons):
        joints = skeleton.positions[
            skeleton.marker_present & np.isfinite(skeleton.positions).all(1)
        ]
        layout = skeleton.layout
        children = layout.link_children
        parents = layout.link_parents
        drawn = skeleton.marker_present[children] & skeleton.marker_present[parents]
        segments = np.stack(
            [skeleton.positions[parents[drawn]], skeleton.positions[children[drawn]]], 1
        )
        segments = segments[np.isfinite(segments).all(axis=(1, 2))].reshape(-1, 3)
        head = joints[:, 2].argmax() if len(joints) else None
        label_at = joints[head] + [0.0, 0.0, 0.25] if head is not None else np.zeros(3)
        base = 3 * index
        color = id_color(skeleton.id)
        data.ids[base : base + 3] = [3 * skeleton.id, 3 * skeleton.id + 1, 3 * skeleton.id + 2]
        data.types[base : base + 3] = [SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING]
        data.colors[base : base + 3] = color
        data.scales[base] = params.joint_size
        data.scales[base + 1] = params.link_width
        data.scales[base + 2] = params.label_height
        data.poses[base + 2, :3] = label_at
        data.points += [joints, segments, np.empty((0, 3))]
        data.texts += ["", "", f"id {skeleton.id}"]
    data.point_colors = [np.empty((0, 4), dtype=np.float32)] * n
    return data
