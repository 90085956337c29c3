"""Skeletons as RViz/Foxglove markers: per person a sphere list, a line list and a label.

Colours come from the skeleton id, so a person keeps their colour from stage to stage and
across frames. Markers carry a short lifetime: a person who leaves disappears by themselves.

``encode_skeleton_markers`` gives the CDR bytes of ``encode_marker_array(skeleton_markers(...))``
without building the columns: for a frame shaped like an earlier one (same people, layout and
visible joints), the earlier message is the template and only the stamps, the label positions
and the points change, in one compiled call.
"""

from __future__ import annotations

import colorsys
from dataclasses import dataclass, fields
from functools import lru_cache

import numpy as np

from hiros_core.cdr import LEAD
from hiros_core.codec import MarkerArrayData, encode_marker_array, marker_array_plan
from hiros_core.layouts import Layout
from hiros_core.model import SkeletonGroup, shared_stack, warm_up_group

__all__ = [
    "LABEL_HEIGHT",
    "VisualizerParams",
    "encode_skeleton_markers",
    "id_color",
    "skeleton_markers",
    "warm_up",
]

SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING = 7, 5, 9
_KINDS = [SPHERE_LIST, LINE_LIST, TEXT_VIEW_FACING]
_NO_POINTS = np.empty((0, 3))
_NO_POINTS.flags.writeable = False
_NO_COLORS = np.empty((0, 4), dtype=np.float32)
_NO_COLORS.flags.writeable = False


LABEL_HEIGHT = 0.12
"""Height (m) of the id label's text, drawn above each skeleton: readable from across a room."""


@dataclass
class VisualizerParams:
    """How skeletons are drawn."""

    joint_size: float = 0.05
    """Diameter (m) of a joint's sphere."""
    link_width: float = 0.02
    """Width (m) of the lines between joints."""
    lifetime: float = 0.25
    """Seconds a marker stays without a newer one (a lost skeleton disappears)."""


@lru_cache(maxsize=1024)
def _id_color(skeleton_id: int) -> tuple[float, float, float, float]:
    hue = (skeleton_id * 0.618033988749895) % 1.0
    return (*colorsys.hsv_to_rgb(hue, 0.75, 0.95), 1.0)


def id_color(skeleton_id: int) -> np.ndarray:
    """A distinct, stable RGBA colour per id (golden-ratio hue steps)."""
    return np.array(_id_color(int(skeleton_id)), dtype=np.float32)


def skeleton_markers(
    group: SkeletonGroup, namespace: str = "", params: VisualizerParams | None = None
) -> MarkerArrayData:
    """Three markers per skeleton (ids ``3*i``, ``3*i+1``, ``3*i+2`` by skeleton id).

    Per person: a sphere list of the present joints, a line list of the links whose both ends
    are present, and a label 25 cm above the highest joint. Every person of one layout is
    drawn with one set of numpy calls; only the per-person point lists are cut apart.
    """
    params = params or VisualizerParams()
    skeletons = group.skeletons
    n = 3 * len(skeletons)
    data = MarkerArrayData.new(n, frame_id=group.frame_id, stamp_ns=group.stamp_ns)
    data.namespaces = [namespace] * n
    data.lifetimes_ns[:] = round(params.lifetime * 1e9)
    data.point_colors = [_NO_COLORS] * n
    if not skeletons:
        data.points, data.texts = [], []
        return data
    ids = [s.id for s in skeletons]
    data.ids[:] = [_marker_id(i, k) for i in ids for k in (0, 1, 2)]
    data.types[:] = _KINDS * len(skeletons)
    data.colors[:] = [_id_color(int(i)) for i in ids for _ in (0, 1, 2)]
    sizes = (params.joint_size, params.link_width, LABEL_HEIGHT) * len(skeletons)
    data.scales[:] = np.array(sizes)[:, None]
    layout = skeletons[0].layout
    if all(s.layout is layout for s in skeletons):
        groups = [(layout, list(range(len(skeletons))))]
    else:
        groups = [(s.layout, [index]) for index, s in enumerate(skeletons)]
    drawn: list[tuple[np.ndarray, np.ndarray]] = [(_NO_POINTS, _NO_POINTS)] * len(skeletons)
    for group_layout, members in groups:
        positions = np.array([skeletons[i].positions for i in members])  # (P, J, 3)
        present = np.array([skeletons[i].marker_present for i in members])
        visible = present & np.isfinite(positions).all(axis=2)
        ends = _link_ends(group_layout)  # parent, child of each link, interleaved
        segments = positions[:, ends]  # (P, 2L, 3): the line list's points in order
        both = visible[:, ends]
        linked = both[:, 0::2] & both[:, 1::2]  # (P, L)
        data.poses[[3 * i + 2 for i in members], :3] = _label_tops(positions, visible)
        whole_bodies = visible.all(axis=1).tolist()
        whole_links = linked.all(axis=1).tolist()
        for row, index in enumerate(members):
            joints = positions[row] if whole_bodies[row] else positions[row][visible[row]]
            lines = (
                segments[row]
                if whole_links[row]
                else segments[row].reshape(-1, 2, 3)[linked[row]].reshape(-1, 3)
            )
            drawn[index] = (joints, lines)
    data.points = [points for joints, lines in drawn for points in (joints, lines, _NO_POINTS)]
    data.texts = [text for i in ids for text in ("", "", f"id {i}")]
    return data


def _marker_id(skeleton_id: int, kind: int) -> int:
    """Marker ``3 * id + kind``, wrapped into int32 (a Marker's id) for ids near its limits.

    A skeleton id from elsewhere may be any int32; without the wrap its markers overflow and
    the whole frame could not be drawn.
    """
    value = 3 * int(skeleton_id) + kind
    return value if -(2**31) <= value < 2**31 else value % 2**31


@lru_cache(maxsize=16)
def _link_ends(layout: Layout) -> np.ndarray:
    """``(2L,)`` parent and child joint of each link, interleaved (a line list's order)."""
    return np.stack([layout.link_parents, layout.link_children], axis=1).ravel()


def _label_tops(positions: np.ndarray, visible: np.ndarray) -> np.ndarray:
    """``(P, 3)`` label positions: 25 cm above each person's highest visible joint (else 0)."""
    height = np.where(visible, positions[..., 2], -np.inf)
    top = positions[np.arange(len(positions)), height.argmax(axis=1)]
    top += (0.0, 0.0, 0.25)
    top[~visible.any(axis=1)] = 0.0
    return top


@dataclass(frozen=True)
class _DrawPlan:
    """One frame shape's encoded message and where its per-frame values go.

    ``template`` holds ``LEAD`` spare bytes then the message (payload 8-byte aligned);
    ``stamps`` are int32 positions of every marker's ``sec`` (``nanosec`` follows); ``tops``
    float64 positions of the labels' x, y, z; ``points`` float64 positions of every point
    coordinate and ``sources`` the matching positions in the frame's ``(P, J, 3)`` positions.
    """

    template: np.ndarray
    size: int
    stamps: np.ndarray
    tops: np.ndarray
    points: np.ndarray
    sources: np.ndarray


_DRAW_PLANS: dict[tuple, _DrawPlan] = {}
_DRAW_PLAN_CAPACITY = 256
_INT32_SECONDS = (-(2**31), 2**31)
_DRAWING_FIELDS = tuple(f.name for f in fields(VisualizerParams))  # not a subclass's topics


def warm_up() -> None:
    """Load the compiled drawing now (numba's disk cache, ~30 ms), not on the first frame."""
    encode_skeleton_markers(warm_up_group(), "warm_up")


def encode_skeleton_markers(
    group: SkeletonGroup, namespace: str = "", params: VisualizerParams | None = None
) -> bytes:
    """``encode_marker_array(skeleton_markers(group, namespace, params))``, faster.

    Frames of a known shape (people, their layout and visible joints, frame, namespace,
    parameters) fill the template of their shape in one compiled call
    (``hiros_visualizer.compiled.draw``); others go the general way once and become the
    template of their shape. The general way is the reference its test holds it equal to.
    """
    from hiros_visualizer.compiled import draw, visible_joints

    params = params or VisualizerParams()
    skeletons = group.skeletons
    sec, nanosec = divmod(group.stamp_ns, 1_000_000_000)
    layout = skeletons[0].layout if skeletons else None
    if (
        not skeletons
        or not _INT32_SECONDS[0] <= sec < _INT32_SECONDS[1]
        or any(s.layout is not layout for s in skeletons)
    ):
        return encode_marker_array(skeleton_markers(group, namespace, params))
    stack = shared_stack(skeletons)
    if stack is not None and stack.markers.dtype == np.float64:
        rows, column, present = stack.markers, 1, stack.marker_present  # no copy
    else:
        rows, column = np.array([s.positions for s in skeletons], dtype=float), 0
        present = np.array([s.marker_present for s in skeletons])
    visible = visible_joints(rows, column, present)
    ids = tuple(s.id for s in skeletons)
    drawing = tuple(getattr(params, name) for name in _DRAWING_FIELDS)
    key = (group.frame_id, namespace, drawing, layout, ids, visible.tobytes())
    plan = _DRAW_PLANS.get(key)
    if plan is None:
        if len(_DRAW_PLANS) >= _DRAW_PLAN_CAPACITY:
            _DRAW_PLANS.clear()
        data = skeleton_markers(group, namespace, params)
        plan = _DRAW_PLANS[key] = _draw_plan(data, encode_marker_array(data), visible, layout)
    out = draw(plan.template, rows, column, visible, plan.points, plan.sources, plan.tops,
               plan.stamps, sec, nanosec)  # fmt: skip
    return out[LEAD : LEAD + plan.size].tobytes()


def _draw_plan(
    data: MarkerArrayData, encoded: bytes, visible: np.ndarray, layout: Layout
) -> _DrawPlan:
    plan = marker_array_plan(data)
    size = len(encoded)
    template = np.zeros(LEAD + size + (-(LEAD + size)) % 8, dtype=np.uint8)
    template[LEAD : LEAD + size] = np.frombuffer(encoded, dtype=np.uint8)
    stamps = (plan.slots["stamp"] + LEAD) // 4
    tops = (plan.slots["pose_scale"][2::3, None] + LEAD) // 8 + np.arange(3)
    n_people, n_joints = visible.shape
    ends = _link_ends(layout).reshape(-1, 2)
    sources = []
    for person in range(n_people):
        linked = visible[person][ends].all(axis=1)
        joints = np.concatenate([np.flatnonzero(visible[person]), ends[linked].ravel()])
        sources.append((person * n_joints + joints)[:, None] * 3 + np.arange(3))
    point_slots = plan.slots.get("points", np.empty(0, dtype=np.intp))
    points = (point_slots[:, None] + LEAD) // 8 + np.arange(3)
    return _DrawPlan(
        template,
        size,
        stamps,
        tops.ravel(),
        points.ravel(),
        np.concatenate(sources).ravel(),
    )
