"""The numpy model of skeletons: what every stage takes and returns.

A skeleton keeps, for each marker (joint) id and each link id, one row of 20 float64::

    [confidence, px, py, pz, qx, qy, qz, qw, vx, vy, vz, wx, wy, wz, ax, ay, az, alx, aly, alz]

i.e. the confidence followed by the message's ``KinematicState`` (pose, twist, accel) in message
order. Rows are dense by id (row ``j`` is marker id ``j``), with a ``present`` mask saying which
ids the message carries; absent rows are NaN. The named properties (``positions``,
``orientations``, ...) are views into those rows, so stages work on ``(J, 3)`` arrays while the
codec moves whole rows in one copy. Units: metres, seconds, quaternions x, y, z, w.
Stamps are integer nanoseconds so that messages round-trip exactly.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from hiros_core.errors import LayoutError
from hiros_core.layouts import AZURE_KINECT, Layout, get_layout

__all__ = [
    "BOX_WIDTH",
    "STATE_WIDTH",
    "Skeleton",
    "SkeletonGroup",
    "SkeletonRows",
    "camera_from_frame",
    "link_rows",
    "ns_to_sec",
    "sec_to_ns",
    "shared_stack",
    "stack_rows",
    "warm_up_group",
]

STATE_WIDTH = 20
"""Floats per marker or link row: confidence + KinematicState (7 pose, 6 twist, 6 accel)."""
BOX_WIDTH = 22
"""Floats of a bounding box: KinematicState (19) + height, length, width."""

_CONFIDENCE = 0
_POSITION = slice(1, 4)
_ORIENTATION = slice(4, 8)
_VELOCITY = slice(8, 11)
_ANGULAR_VELOCITY = slice(11, 14)
_ACCELERATION = slice(14, 17)
_ANGULAR_ACCELERATION = slice(17, 20)


def ns_to_sec(stamp_ns: int) -> float:
    """Nanoseconds to float seconds."""
    return stamp_ns * 1e-9


def sec_to_ns(stamp: float) -> int:
    """Float seconds to integer nanoseconds (rounded to the nearest)."""
    return round(stamp * 1e9)


def camera_from_frame(frame_id: str) -> str:
    """The camera name a frame belongs to: ``k01_depth_camera_link`` -> ``k01``.

    DESIGN.md names cameras by their topic namespace; Azure Kinect driver frames are
    ``<prefix>depth_camera_link`` with the prefix ``<cam>_`` by convention.
    """
    for suffix in ("_depth_camera_link", "depth_camera_link"):
        if frame_id.endswith(suffix) and len(frame_id) > len(suffix):
            return frame_id[: -len(suffix)].rstrip("_/")
    return frame_id.strip("/")


def _nan_rows(count: int, width: int = STATE_WIDTH) -> np.ndarray:
    return np.full((count, width), np.nan)


def link_rows(
    markers: np.ndarray, marker_present: np.ndarray, layout: Layout
) -> tuple[np.ndarray, np.ndarray]:
    """Link rows ``(..., J, 20)`` and link presence ``(..., J)`` from marker rows.

    A link is present where both its end joints are: its position is their midpoint, its
    orientation the child joint's, its confidence the smaller one (``fmin``); every other row is
    NaN. Any leading shape (one skeleton or a stack of them) in one pass: a fixed dozen numpy
    calls, so stages rebuild the links of all their people at once. When the link ids form
    one run (every built-in layout: all joints but the root), the rows are written in place
    through a slice instead of gathered and scattered. Float64 rows (all the model makes)
    take the compiled form in ``hiros_core.compiled``, the same in one call, bit for bit;
    other dtypes the numpy form.
    """
    parents, children = layout.link_parents, layout.link_children
    if markers.dtype == np.float64:
        from hiros_core import compiled

        return compiled.link_rows(markers, marker_present, parents, children)
    return _numpy_link_rows(markers, marker_present, layout)


def _numpy_link_rows(
    markers: np.ndarray, marker_present: np.ndarray, layout: Layout
) -> tuple[np.ndarray, np.ndarray]:
    """``link_rows`` in numpy calls (the reference the compiled form is tested against)."""
    parents, children = layout.link_parents, layout.link_children
    rows = _children_slice(layout)
    shape = marker_present.shape
    parent_rows = markers[..., parents, : _ORIENTATION.start]  # confidence, position
    child_rows = markers[..., rows, : _ORIENTATION.stop]
    links = np.full((*shape, STATE_WIDTH), np.nan)
    values = links[..., rows, : _ORIENTATION.stop]  # a view when ``rows`` is a slice
    np.fmin(parent_rows[..., _CONFIDENCE], child_rows[..., _CONFIDENCE], out=values[..., 0])
    position = values[..., _POSITION]
    np.add(child_rows[..., _POSITION], parent_rows[..., _POSITION], out=position)
    position *= 0.5
    values[..., _ORIENTATION] = child_rows[..., _ORIENTATION]
    both = marker_present[..., parents] & marker_present[..., rows]
    values[~both] = np.nan
    if not isinstance(rows, slice):
        links[..., children, : _ORIENTATION.stop] = values
    present = np.zeros(shape, dtype=bool)
    present[..., rows] = both
    return links, present


_CHILD_SLICES: dict[int, tuple[Layout, slice | np.ndarray]] = {}


def _children_slice(layout: Layout) -> slice | np.ndarray:
    """The layout's link ids as a slice when they are consecutive, else as the index array."""
    found = _CHILD_SLICES.get(id(layout))
    if found is None or found[0] is not layout:
        children = np.asarray(layout.link_children)
        rows: slice | np.ndarray = children
        if children.size and np.array_equal(children, np.arange(children[0], children[-1] + 1)):
            rows = slice(int(children[0]), int(children[-1]) + 1)
        found = _CHILD_SLICES[id(layout)] = (layout, rows)
    return found[1]


@dataclass(eq=False)
class Skeleton:
    """One person's skeleton as seen at one instant.

    Attributes:
        id: track or body id (``-1`` when unknown).
        src_time_ns: stamp of the source camera frame, integer nanoseconds.
        src_frame: frame id of the source camera (or the world frame after merging).
        layout: which joint each marker id is.
        markers: ``(J, 20)`` rows by marker id (see module docstring).
        links: ``(L, 20)`` rows by link id (link id = child joint id).
        marker_present: ``(J,)`` which marker ids the skeleton carries.
        link_present: ``(L,)`` which link ids the skeleton carries.
        confidence: whole-skeleton confidence, NaN when unknown.
        bounding_box: ``(22,)`` KinematicState of the box centre + height, length, width.
        max_markers: the message field; the layout's joint count by default.
        max_links: the message field; the layout's link count by default.

    """

    id: int
    src_time_ns: int
    src_frame: str
    layout: Layout
    markers: np.ndarray
    links: np.ndarray
    marker_present: np.ndarray
    link_present: np.ndarray
    confidence: float = math.nan
    bounding_box: np.ndarray = field(default_factory=lambda: np.full(BOX_WIDTH, np.nan))
    max_markers: int = -1
    max_links: int = -1
    _rows: tuple[SkeletonRows, int, tuple[object, ...]] | None = field(
        default=None, init=False, repr=False, compare=False
    )
    """The stack this skeleton's fields are row ``[1]`` of, and the ``base`` of every view of
    each of its fields (set by ``SkeletonRows.skeletons``; ``shared_stack`` checks them)."""

    def __post_init__(self) -> None:
        if self.max_markers < 0:
            self.max_markers = self.layout.n_joints
        if self.max_links < 0:
            self.max_links = self.layout.n_links

    @classmethod
    def empty(
        cls,
        layout: Layout = AZURE_KINECT,
        *,
        skeleton_id: int = -1,
        src_time_ns: int = 0,
        src_frame: str = "",
    ) -> Skeleton:
        """A skeleton with no markers and no links (all rows NaN, nothing present)."""
        return cls(
            id=skeleton_id,
            src_time_ns=src_time_ns,
            src_frame=src_frame,
            layout=layout,
            markers=_nan_rows(layout.n_joints),
            links=_nan_rows(layout.n_links),
            marker_present=np.zeros(layout.n_joints, dtype=bool),
            link_present=np.zeros(layout.n_links, dtype=bool),
        )

    @classmethod
    def from_positions(
        cls,
        positions: np.ndarray,
        layout: Layout = AZURE_KINECT,
        *,
        skeleton_id: int = -1,
        src_time_ns: int = 0,
        src_frame: str = "",
        confidences: np.ndarray | None = None,
        orientations: np.ndarray | None = None,
    ) -> Skeleton:
        """A skeleton from ``(J, 3)`` joint positions; joints with any NaN coordinate are absent.

        Links are present where both end joints are; their orientation is the child joint's
        orientation when given (the Azure SDK's convention), their position the midpoint.
        """
        positions = np.asarray(positions, dtype=float)
        return cls.many_from_positions(
            positions[None],
            layout,
            skeleton_ids=(skeleton_id,),
            src_time_ns=src_time_ns,
            src_frame=src_frame,
            confidences=None if confidences is None else np.asarray(confidences)[None],
            orientations=None if orientations is None else np.asarray(orientations)[None],
        )[0]

    @classmethod
    def many_from_positions(
        cls,
        positions: np.ndarray,
        layout: Layout = AZURE_KINECT,
        *,
        skeleton_ids: Sequence[int],
        src_time_ns: int = 0,
        src_frame: str = "",
        confidences: np.ndarray | None = None,
        orientations: np.ndarray | None = None,
    ) -> list[Skeleton]:
        """:meth:`from_positions` of ``(P, J, 3)`` positions at once (one per id).

        ``confidences`` ``(P, J)`` and ``orientations`` ``(P, J, 4)`` as there. The skeletons'
        rows are views into arrays shared by them alone (distinct rows, so changing one
        skeleton never changes another); a bridge frame costs a fixed number of numpy calls
        whatever the number of people.
        """
        positions = np.asarray(positions, dtype=float)
        n_people, n_joints = positions.shape[:2]
        present = np.isfinite(positions).all(axis=2)
        markers = np.full((n_people, n_joints, STATE_WIDTH), np.nan)
        markers[..., _POSITION] = np.where(present[..., None], positions, np.nan)
        if confidences is not None:
            markers[..., _CONFIDENCE] = np.where(present, confidences, np.nan)
        if orientations is not None:
            markers[..., _ORIENTATION] = np.where(present[..., None], orientations, np.nan)
        return cls.many_from_rows(
            markers, present, layout, skeleton_ids=skeleton_ids, src_time_ns=src_time_ns,
            src_frame=src_frame,
        )  # fmt: skip

    @classmethod
    def many_from_rows(
        cls,
        markers: np.ndarray,
        marker_present: np.ndarray,
        layout: Layout = AZURE_KINECT,
        *,
        skeleton_ids: Sequence[int],
        src_time_ns: int = 0,
        src_frame: str = "",
    ) -> list[Skeleton]:
        """Skeletons from ``(P, J, 20)`` marker rows (taken, not copied) and ``(P, J)`` presence.

        Links are built as :meth:`update_links` does, for all people at once; each skeleton's
        arrays are views of distinct rows of arrays shared by these skeletons alone.
        """
        links, link_present = link_rows(markers, marker_present, layout)
        boxes = np.full((len(markers), BOX_WIDTH), np.nan)
        rows = SkeletonRows(markers, marker_present, links, link_present, boxes)
        return rows.skeletons(skeleton_ids, src_time_ns, src_frame, layout)

    def update_links(self) -> None:
        """Recompute link rows from marker rows: midpoint, child orientation, min confidence."""
        links, present = link_rows(self.markers, self.marker_present, self.layout)
        self.links[:] = links
        self.link_present[:] = present

    # Views into the marker rows: (J,) or (J, k), writable.
    @property
    def confidences(self) -> np.ndarray:
        """``(J,)`` joint confidences (0..1, or the driver's level), NaN when unknown."""
        return self.markers[:, _CONFIDENCE]

    @property
    def positions(self) -> np.ndarray:
        """``(J, 3)`` joint positions in metres."""
        return self.markers[:, _POSITION]

    @property
    def orientations(self) -> np.ndarray:
        """``(J, 4)`` joint orientations, quaternions x, y, z, w."""
        return self.markers[:, _ORIENTATION]

    @property
    def velocities(self) -> np.ndarray:
        """``(J, 3)`` linear joint velocities in m/s."""
        return self.markers[:, _VELOCITY]

    @property
    def angular_velocities(self) -> np.ndarray:
        """``(J, 3)`` angular joint velocities in rad/s."""
        return self.markers[:, _ANGULAR_VELOCITY]

    @property
    def accelerations(self) -> np.ndarray:
        """``(J, 3)`` linear joint accelerations in m/s^2."""
        return self.markers[:, _ACCELERATION]

    @property
    def angular_accelerations(self) -> np.ndarray:
        """``(J, 3)`` angular joint accelerations in rad/s^2."""
        return self.markers[:, _ANGULAR_ACCELERATION]

    @property
    def link_orientations(self) -> np.ndarray:
        """``(L, 4)`` link orientations, quaternions x, y, z, w."""
        return self.links[:, _ORIENTATION]

    @property
    def src_time(self) -> float:
        """Source stamp in float seconds."""
        return ns_to_sec(self.src_time_ns)

    @property
    def camera(self) -> str:
        """Name of the source camera, from ``src_frame``."""
        return camera_from_frame(self.src_frame)

    def copy(self) -> Skeleton:
        """A deep copy (arrays copied, layout shared)."""
        return Skeleton(
            id=self.id,
            src_time_ns=self.src_time_ns,
            src_frame=self.src_frame,
            layout=self.layout,
            markers=self.markers.copy(),
            links=self.links.copy(),
            marker_present=self.marker_present.copy(),
            link_present=self.link_present.copy(),
            confidence=self.confidence,
            bounding_box=self.bounding_box.copy(),
            max_markers=self.max_markers,
            max_links=self.max_links,
        )

    def same_as(self, other: Skeleton) -> bool:
        """True when both carry the same fields, NaN equal to NaN (for tests and checks)."""
        return (
            self.id == other.id
            and self.src_time_ns == other.src_time_ns
            and self.src_frame == other.src_frame
            # an empty skeleton carries no layout in a message: compare layouts when it matters
            and (
                self.layout.joint_names == other.layout.joint_names
                or not (self.marker_present.any() or self.link_present.any())
            )
            and self.max_markers == other.max_markers
            and self.max_links == other.max_links
            and np.array_equal(
                np.flatnonzero(self.marker_present), np.flatnonzero(other.marker_present)
            )
            and np.array_equal(
                np.flatnonzero(self.link_present), np.flatnonzero(other.link_present)
            )
            and _same_floats(self.markers[self.marker_present], other.markers[other.marker_present])
            and _same_floats(self.links[self.link_present], other.links[other.link_present])
            and _same_floats(np.array([self.confidence]), np.array([other.confidence]))
            and _same_floats(self.bounding_box, other.bounding_box)
        )


def _same_floats(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


class SkeletonRows(NamedTuple):
    """Several skeletons' rows, one array per field: row ``p`` is skeleton ``p``.

    Stages work on a frame's people at once; when the skeletons are views of one such stack
    (the reader, the bridge, the merger and the tracker make them so), ``stack_rows`` hands the
    stack back without copying a row.
    """

    markers: np.ndarray  # (P, J, 20)
    marker_present: np.ndarray  # (P, J)
    links: np.ndarray  # (P, L, 20)
    link_present: np.ndarray  # (P, L)
    bounding_boxes: np.ndarray  # (P, 22)

    def skeletons(
        self,
        skeleton_ids: Sequence[int],
        src_time_ns: int | Sequence[int],
        src_frame: str | Sequence[str],
        layout: Layout | Sequence[Layout],
        confidences: Sequence[float] | None = None,
        *,
        max_sizes: Sequence[tuple[int, int]] | None = None,
    ) -> list[Skeleton]:
        """One skeleton per row, its fields views of the row (taken, not copied).

        ``src_time_ns``, ``src_frame`` and ``layout`` are one value for all or one per row
        (layouts of one size: a pickled group may carry equal layouts as distinct objects);
        ``max_sizes`` the ``(max_markers, max_links)`` of each row, by default its layout's.
        The skeletons remember the stack, so ``stack_rows`` of them, in this order, returns it
        as it is.
        """
        markers, present, links, link_present, boxes = self
        count = len(markers)
        stamps = [src_time_ns] * count if isinstance(src_time_ns, int) else src_time_ns
        frames = [src_frame] * count if isinstance(src_frame, str) else src_frame
        layouts = [layout] * count if isinstance(layout, Layout) else layout
        scores = [math.nan] * count if confidences is None else confidences
        sizes = [(lay.n_joints, lay.n_links) for lay in layouts] if max_sizes is None else max_sizes
        made = []
        # Positional arguments in field order: this runs for every person of every frame.
        for p, skeleton_id in enumerate(skeleton_ids):
            made.append(Skeleton(
                int(skeleton_id), stamps[p], frames[p], layouts[p], markers[p], links[p],
                present[p], link_present[p], scores[p], boxes[p], *sizes[p],
            ))  # fmt: skip
        if made:
            first = made[0]  # numpy makes any view's ``base`` its owner: the same for every row
            roots = (first.markers.base, first.marker_present.base, first.links.base,
                     first.link_present.base, first.bounding_box.base)  # fmt: skip
            for p, skeleton in enumerate(made):
                skeleton._rows = (self, p, roots)
        return made


def stack_rows(skeletons: Sequence[Skeleton]) -> SkeletonRows:
    """The skeletons' rows stacked, ``(P, J, 20)`` and so on; they must share their sizes.

    When the skeletons are rows ``a, a+1, ...`` of one ``SkeletonRows`` and still hold its
    views, the result is that stack (or a slice of it): no row is copied, and a frame's
    skeletons usually come so. Otherwise each field is stacked into new arrays. So treat the
    result as read-only: writing to it may write to the skeletons.
    """
    stacked = shared_stack(skeletons)
    if stacked is not None:
        return stacked
    return SkeletonRows(
        np.array([s.markers for s in skeletons]),
        np.array([s.marker_present for s in skeletons]),
        np.array([s.links for s in skeletons]),
        np.array([s.link_present for s in skeletons]),
        np.array([s.bounding_box for s in skeletons]),
    )


def shared_stack(skeletons: Sequence[Skeleton]) -> SkeletonRows | None:
    """The stack (or a slice of it) the skeletons are consecutive rows of, or None."""
    place = skeletons[0]._rows if skeletons else None
    if place is None:
        return None
    rows, first, roots = place
    markers_root, present_root, links_root, link_present_root, boxes_root = roots
    p = first
    for skeleton in skeletons:
        place = skeleton._rows
        if (
            place is None
            or place[0] is not rows
            or place[1] != p
            # a field replaced since (views of one owner share its ``base``)
            or skeleton.markers.base is not markers_root
            or skeleton.marker_present.base is not present_root
            or skeleton.links.base is not links_root
            or skeleton.link_present.base is not link_present_root
            or skeleton.bounding_box.base is not boxes_root
        ):
            return None
        p += 1
    if first == 0 and len(skeletons) == len(rows.markers):
        return rows
    return SkeletonRows(*(field[first : first + len(skeletons)] for field in rows))


@dataclass(eq=False)
class SkeletonGroup:
    """All skeletons of one camera frame (or one pipeline output instant).

    Attributes:
        stamp_ns: header stamp, integer nanoseconds.
        frame_id: header frame (camera frame before the tracker, world frame after).
        skeletons: the people, in message order.

    """

    stamp_ns: int
    frame_id: str
    skeletons: list[Skeleton] = field(default_factory=list)

    @property
    def stamp(self) -> float:
        """Header stamp in float seconds."""
        return ns_to_sec(self.stamp_ns)

    @property
    def camera(self) -> str:
        """Name of the camera the group came from, from ``frame_id``."""
        return camera_from_frame(self.frame_id)

    @property
    def ids(self) -> np.ndarray:
        """``(P,)`` skeleton ids."""
        return np.array([s.id for s in self.skeletons], dtype=np.int64)

    def positions(self) -> np.ndarray:
        """``(P, J, 3)`` stacked joint positions; all skeletons must share one layout size."""
        if not self.skeletons:
            return np.empty((0, 0, 3))
        return np.array([s.positions for s in self.skeletons])

    def confidences(self) -> np.ndarray:
        """``(P, J)`` stacked joint confidences."""
        if not self.skeletons:
            return np.empty((0, 0))
        return np.array([s.confidences for s in self.skeletons])

    def copy(self) -> SkeletonGroup:
        """A deep copy."""
        return SkeletonGroup(self.stamp_ns, self.frame_id, [s.copy() for s in self.skeletons])

    def same_as(self, other: SkeletonGroup) -> bool:
        """Field-wise equality with NaN equal to NaN."""
        return (
            self.stamp_ns == other.stamp_ns
            and self.frame_id == other.frame_id
            and len(self.skeletons) == len(other.skeletons)
            and all(a.same_as(b) for a, b in zip(self.skeletons, other.skeletons, strict=True))
        )

    def __reduce__(self) -> tuple:
        """Pickle the skeletons as stacked arrays.

        The offline runner hands groups from process to process; pickled one by one, each
        skeleton costs eight arrays and its layout, so a dozen people cost ~100 pickled objects.
        Stacked, a group costs six arrays and a few short lists whatever its size. Skeletons
        of different sizes (mixed layouts) fall back to pickling each skeleton.
        """
        return (_unpickle_group, (self.stamp_ns, self.frame_id, _stack(self.skeletons)))


def _layout_ref(layout: Layout) -> str | Layout:
    """A built-in layout by name (unpickled as the same object), any other by value."""
    try:
        return layout.name if get_layout(layout.name) is layout else layout
    except LayoutError:
        return layout


def _stack(skeletons: list[Skeleton]) -> tuple | list[Skeleton]:
    """The skeletons' fields stacked (one array per field), or the list when sizes differ."""
    shapes = {(s.markers.shape, s.links.shape) for s in skeletons}
    if len(shapes) != 1:
        return skeletons
    scalars = [
        (s.id, s.src_time_ns, s.src_frame, _layout_ref(s.layout), s.confidence,
         s.max_markers, s.max_links)
        for s in skeletons
    ]  # fmt: skip
    return (scalars, *stack_rows(skeletons))


def _unpickle_group(stamp_ns: int, frame_id: str, stacked: tuple | list[Skeleton]) -> SkeletonGroup:
    """Rebuild a group pickled by ``SkeletonGroup.__reduce__`` (skeletons view distinct rows)."""
    if isinstance(stacked, list):
        return SkeletonGroup(stamp_ns, frame_id, stacked)
    columns = zip(*stacked[0], strict=True)  # one tuple per scalar field of ``_stack``
    ids, stamps, frames, layouts, confidences, max_markers, max_links = columns
    skeletons = SkeletonRows(*stacked[1:]).skeletons(
        ids, stamps, frames,
        [get_layout(layout) if isinstance(layout, str) else layout for layout in layouts],
        confidences, max_sizes=list(zip(max_markers, max_links, strict=True)),
    )  # fmt: skip
    return SkeletonGroup(stamp_ns, frame_id, skeletons)


def warm_up_group() -> SkeletonGroup:
    """One Azure Kinect person at the origin: what the warm-ups push through compiled paths.

    The skeleton's rows are one stack's, as the stages make them, so the encoder and the
    drawing take their stacked paths with it.
    """
    people = Skeleton.many_from_positions(
        np.zeros((1, AZURE_KINECT.n_joints, 3)), AZURE_KINECT, skeleton_ids=[1]
    )
    return SkeletonGroup(1, "warm_up", people)
