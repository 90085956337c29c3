"""What the visualizer draws beside the skeletons, and the markers of people who left.

* velocity and acceleration arrows (one ARROW per joint, from the joint to where the motion
  would take it in ``ARROW_TIME`` seconds: ``v t`` and ``a t^2`` metres), off by default;
* joint-angle text next to the joints asked for (``hiros_eval.body.JOINT_ANGLES``, degrees);
* per-joint transforms (a TF frame per joint of each person) for tools that follow frames;
* ``Drawing``: per topic, what was drawn, so that a person who left has their markers
  deleted (DELETE) with the next frame instead of when their lifetime runs out, and
  everything (DELETEALL) when the stream ends.

Each kind of marker has its own namespace (``<ns>``, ``<ns>/velocity``,
``<ns>/acceleration``, ``<ns>/angles``), so RViz and Foxglove can show or hide it alone.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from hiros_core.codec import MarkerArrayData, encode_marker_array
from hiros_core.errors import ConfigError, LayoutError
from hiros_core.frames import StaticTransform
from hiros_core.layouts import Layout
from hiros_core.model import Skeleton, SkeletonGroup
from hiros_eval.body import JOINT_ANGLES, joint_angles
from hiros_visualizer.markers import VisualizerParams, encode_skeleton_markers, id_color

__all__ = [
    "ARROW",
    "ARROW_TIME",
    "DELETE",
    "DELETEALL",
    "Drawing",
    "OverlayParams",
    "angle_markers",
    "arrow_markers",
    "joint_transforms",
    "overlays_from_names",
]

ARROW, TEXT_VIEW_FACING = 0, 9
DELETE, DELETEALL = 2, 3
_JOINT_SLOTS = 64  # marker ids per person in the per-joint namespaces (layouts have <= 32 joints)
_MIN_ARROW = 0.005  # m: shorter arrows (a joint at rest) are not drawn

ARROW_TIME = 0.2
"""Seconds: an arrow reaches where the joint would be after this time (``v t``, ``a t^2`` m),
long enough to see a walk's arrows, short enough not to cross the room."""


@dataclass
class OverlayParams:
    """What is drawn beside the skeletons (all off by default)."""

    velocity_arrows: bool = False
    """Draw an arrow per joint to where its velocity would take it after ``ARROW_TIME``."""
    acceleration_arrows: bool = False
    """Draw an arrow per joint of its acceleration times ``ARROW_TIME`` squared."""
    joint_angles: list[str] = field(default_factory=list)
    """Angles to print beside their joint, by name (``knee_left``, ``elbow_right``, ...)."""


def overlays_from_names(names: Iterable[str]) -> OverlayParams:
    """The overlays of a list of names, as a command line gives them.

    A name is ``velocity`` or ``acceleration`` (arrows), a joint angle's (``knee_left``: its
    value beside the joint) or ``angles`` (every angle): ``hiros run --overlays
    velocity,knee_left``. The visualizer node takes the same choices as its parameters.

    Raises:
        ConfigError: a name that is none of these, with the choices.

    """
    names = list(dict.fromkeys(names))  # in order, once each
    choices = ["velocity", "acceleration", "angles", *JOINT_ANGLES]
    unknown = [n for n in names if n not in choices]
    if unknown:
        msg = f"unknown overlays {', '.join(unknown)}: choose among {', '.join(choices)}"
        raise ConfigError(msg)
    angles = list(JOINT_ANGLES) if "angles" in names else [n for n in names if n in JOINT_ANGLES]
    return OverlayParams(
        velocity_arrows="velocity" in names,
        acceleration_arrows="acceleration" in names,
        joint_angles=angles,
    )


def _slot(skeleton_id: int, index: int, slots: int = _JOINT_SLOTS) -> int:
    """Marker id ``slots * id + index``, wrapped into int32."""
    value = slots * int(skeleton_id) + index
    return value if -(2**31) <= value < 2**31 else value % 2**31


def _markers(
    group: SkeletonGroup, rows: list[tuple[str, int, int, np.ndarray, str]], scale: np.ndarray
) -> MarkerArrayData:
    """Markers of ``(namespace, id, type, points or position (k, 3), text)`` rows."""
    data = MarkerArrayData.new(len(rows), frame_id=group.frame_id, stamp_ns=group.stamp_ns)
    data.namespaces = [r[0] for r in rows]
    data.ids[:] = [r[1] for r in rows]
    data.types[:] = [r[2] for r in rows]
    data.scales[:] = scale
    data.points = [r[3] if r[2] == ARROW else np.empty((0, 3)) for r in rows]
    data.point_colors = [np.empty((0, 4), dtype=np.float32)] * len(rows)
    data.texts = [r[4] for r in rows]
    for i, row in enumerate(rows):
        if row[2] != ARROW:
            data.poses[i, :3] = row[3][0]
    return data


def arrow_markers(
    group: SkeletonGroup, namespace: str, kind: str, params: OverlayParams, lifetime: float
) -> MarkerArrayData:
    """``kind`` (``velocity`` or ``acceleration``) arrows of every joint that moves.

    Marker ids are ``64 * skeleton id + joint`` in ``<namespace>/<kind>``; colours are the
    person's, darker for accelerations.
    """
    seconds = ARROW_TIME if kind == "velocity" else ARROW_TIME**2
    rows, colors = [], []
    for skeleton in group.skeletons:
        vectors = skeleton.velocities if kind == "velocity" else skeleton.accelerations
        ends = skeleton.positions + seconds * vectors
        drawn = skeleton.marker_present & np.isfinite(ends).all(axis=1)
        drawn &= np.linalg.norm(seconds * np.nan_to_num(vectors), axis=1) >= _MIN_ARROW
        color = id_color(skeleton.id) * (1.0 if kind == "velocity" else 0.6)
        for joint in np.flatnonzero(drawn):
            segment = np.stack([skeleton.positions[joint], ends[joint]])
            rows.append((f"{namespace}/{kind}", _slot(skeleton.id, int(joint)), ARROW, segment, ""))
            colors.append(color)
    data = _markers(group, rows, np.array([0.01, 0.025, 0.03]))  # shaft, head width, head
    data.colors[:, :3] = np.array(colors)[:, :3] if colors else data.colors[:, :3]
    data.lifetimes_ns[:] = round(lifetime * 1e9)
    return data


def _angles_of(skeleton: Skeleton, names: list[str]) -> list[tuple[int, str, float]]:
    """``(name's index, text, where joint)`` for each asked angle this skeleton's layout has."""
    layout: Layout = skeleton.layout
    try:
        values = joint_angles(skeleton.positions, layout)
        vertex = {n: layout.index(JOINT_ANGLES[n][1][0]) for n in names}
    except LayoutError:  # a layout without the Azure Kinect joint names
        return []
    return [
        (i, f"{name} {values[name]:.0f}°", vertex[name])
        for i, name in enumerate(names)
        if np.isfinite(values[name])
    ]


def angle_markers(
    group: SkeletonGroup, namespace: str, names: list[str], lifetime: float
) -> MarkerArrayData:
    """Each asked joint angle as text beside its joint (``<namespace>/angles``)."""
    unknown = sorted(set(names) - set(JOINT_ANGLES))
    if unknown:
        msg = f"unknown joint angles {unknown}: choose among {sorted(JOINT_ANGLES)}"
        raise ValueError(msg)
    rows = []
    for skeleton in group.skeletons:
        for index, text, joint in _angles_of(skeleton, names):
            at = skeleton.positions[joint][None] + (0.08, 0.0, 0.0)
            rows.append(
                (f"{namespace}/angles", _slot(skeleton.id, index), TEXT_VIEW_FACING, at, text)
            )
    data = _markers(group, rows, np.array([0.0, 0.0, 0.06]))
    data.lifetimes_ns[:] = round(lifetime * 1e9)
    return data


def joint_transforms(group: SkeletonGroup, prefix: str = "") -> list[StaticTransform]:
    """A TF frame per known joint: ``<frame> -> <prefix>person_<id>/<joint name>``.

    Joints without an orientation get the frame's axes (identity rotation).
    """
    out = []
    identity = np.array([0.0, 0.0, 0.0, 1.0])
    for skeleton in group.skeletons:
        names = skeleton.layout.joint_names
        known = skeleton.marker_present & np.isfinite(skeleton.positions).all(axis=1)
        for joint in np.flatnonzero(known):
            rotation = skeleton.orientations[joint]
            if not (np.isfinite(rotation).all() and np.linalg.norm(rotation) > 0.5):
                rotation = identity
            child = f"{prefix}person_{skeleton.id}/{names[joint]}"
            out.append(
                StaticTransform(group.frame_id, child, skeleton.positions[joint].copy(), rotation)
            )
    return out


class Drawing:
    """The MarkerArray messages of one topic, frame after frame.

    ``draw`` gives the messages for a group: first the deletion of what people who left had
    drawn (if any), then the skeletons (``encode_skeleton_markers``), then each overlay that
    is on. Keeps which people are drawn, in which layout, to know what to delete.

    An empty group changes nothing: stages publish one between their outputs (the merger's
    for a camera frame that completed no fused frame), so it does not say that people left.
    ``finish`` deletes everything once the stream ends.
    """

    def __init__(
        self,
        namespace: str,
        params: VisualizerParams | None = None,
        overlays: OverlayParams | None = None,
    ) -> None:
        self.namespace = namespace
        self.params = params or VisualizerParams()
        self.overlays = overlays or OverlayParams()
        angle_markers(SkeletonGroup(0, "", []), namespace, self.overlays.joint_angles, 0.0)
        self._drawn: dict[int, int] = {}  # skeleton id -> joints of its layout

    def draw(self, group: SkeletonGroup) -> list[bytes]:
        """Encoded MarkerArrays for ``group``, in publishing order (possibly none)."""
        if not group.skeletons:
            return []
        messages = []
        now = {int(s.id): s.layout.n_joints for s in group.skeletons}
        left = sorted(set(self._drawn) - set(now))
        if left:
            messages.append(encode_marker_array(self._deletions(group, left)))
        self._drawn = now
        messages.append(encode_skeleton_markers(group, self.namespace, self.params))
        lifetime = self.params.lifetime
        for kind in ("velocity", "acceleration"):
            if getattr(self.overlays, f"{kind}_arrows"):
                arrows = arrow_markers(group, self.namespace, kind, self.overlays, lifetime)
                messages.append(encode_marker_array(arrows))
        if self.overlays.joint_angles:
            angles = angle_markers(group, self.namespace, self.overlays.joint_angles, lifetime)
            messages.append(encode_marker_array(angles))
        return messages

    def finish(self, stamp_ns: int, frame_id: str = "") -> list[bytes]:
        """One DELETEALL when anything is drawn: the stream ended, nobody is left."""
        if not self._drawn:
            return []
        self._drawn = {}
        data = MarkerArrayData.new(1, frame_id=frame_id, stamp_ns=stamp_ns)
        data.actions[:] = DELETEALL
        data.namespaces = [""]
        return [encode_marker_array(data)]

    def _deletions(self, group: SkeletonGroup, left: list[int]) -> MarkerArrayData:
        """DELETE for every marker of the people who left."""
        keys = [(self.namespace, 3 * s + k) for s in left for k in range(3)]
        per_joint = [f"{self.namespace}/{kind}" for kind in ("velocity", "acceleration")
                     if getattr(self.overlays, f"{kind}_arrows")]  # fmt: skip
        keys += [(ns, _slot(s, j)) for ns in per_joint for s in left for j in range(self._drawn[s])]
        angles = len(self.overlays.joint_angles)
        keys += [(f"{self.namespace}/angles", _slot(s, i)) for s in left for i in range(angles)]
        data = MarkerArrayData.new(len(keys), frame_id=group.frame_id, stamp_ns=group.stamp_ns)
        data.actions[:] = DELETE
        data.namespaces = [ns for ns, _ in keys]
        data.ids[:] = [_wrap(i) for _, i in keys]
        return data


def _wrap(value: int) -> int:
    return value if -(2**31) <= value < 2**31 else value % 2**31
