"""What the tracker derives from a skeleton layout: mirror parts, body frame, side pairs, weights.

Computed once per layout (``functools.cache``) and bundled per frame in ``_LayoutInfo``; the
kernels take them as ``kernel_args`` tuples. Shapes: ``J`` joints, ``K`` mirror parts.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache, cached_property

import numpy as np

from hiros_core.layouts import Layout
from hiros_tracker.kernel_args import FacingBody, HitLayout, MirrorLayout, SideLayout


@dataclass(frozen=True, eq=False)
class _MirrorParts:
    """A layout's left/right structure.

    Attributes:
        mirror: ``(J,)`` the layout's left/right permutation.
        part: ``(J,)`` mirror part of each joint, ``-1`` on the midline.
        onehot: ``(J, K)`` part membership.

    """

    mirror: np.ndarray
    part: np.ndarray
    onehot: np.ndarray

    @property
    def count(self) -> int:
        """Number of parts K."""
        return self.onehot.shape[1]

    @cached_property
    def arrays(self) -> MirrorLayout:
        """The parts as the kernels take them."""
        return MirrorLayout(self.part, self.mirror, self.count)

    @cached_property
    def _table(self) -> np.ndarray:
        """``(2**K, J)`` the joint order of every combination of flipped parts."""
        combos = (np.arange(2**self.count)[:, None] >> np.arange(self.count)) & 1
        sided = self.part >= 0
        flipped = np.zeros((len(combos), len(self.part)), dtype=bool)
        flipped[:, sided] = combos[:, self.part[sided]].astype(bool)
        return np.where(flipped, self.mirror, np.arange(len(self.part)))

    def permutation(self, flips: np.ndarray) -> np.ndarray:
        """``(..., J)`` joint order relabelling the parts flagged in ``flips`` ``(..., K)``."""
        return self._table[flips.astype(np.int64) @ (1 << np.arange(self.count))]


@cache
def _mirror_parts(layout: Layout) -> _MirrorParts:
    """Split a layout into mirror parts: a sided joint belongs to its topmost sided ancestor."""
    mirror, parents = layout.mirror, layout.parents
    roots = []
    for joint in range(layout.n_joints):
        if mirror[joint] == joint:
            roots.append(-1)
            continue
        top = joint
        while parents[top] >= 0 and mirror[parents[top]] != parents[top]:
            top = parents[top]
        roots.append(min(top, int(mirror[top])))
    keys = sorted({r for r in roots if r >= 0})
    part = np.array([keys.index(r) if r >= 0 else -1 for r in roots], dtype=np.int64)
    onehot = np.zeros((layout.n_joints, len(keys)))
    onehot[part >= 0, part[part >= 0]] = 1.0
    return _MirrorParts(mirror, part, onehot)


@dataclass(frozen=True, eq=False)
class _BodyFrame:
    """Joints giving a body's up, its left and its anatomical forward (feet, nose).

    The front (from the left/right labels) and the forward (from where the feet and the nose
    point, whatever their labels; both computed in ``kernels.facing_evidence``) agree on a
    correctly labelled, unflipped detection; a front/back flip (reflected body, swapped
    labels) reverses the forward against the true front, a side swap reverses the front.
    """

    root: int
    neck: int
    left: np.ndarray  # hip and shoulder on the left (``Layout.body.sides``)
    right: np.ndarray
    feet: np.ndarray  # (2, 2) ankle -> foot, left and right
    head: np.ndarray  # (2,) head -> nose, or empty

    @property
    def usable(self) -> bool:
        """Whether the layout names enough joints."""
        return self.neck >= 0 and len(self.left) == 2 and (len(self.feet) or len(self.head))

    @cached_property
    def pointers(self) -> np.ndarray:
        """``(k, 2)`` joint pairs pointing forward: ankle -> foot, head -> nose."""
        return np.concatenate([self.feet, self.head.reshape(-1, 2)]).astype(np.int64)


@cache
def _body_frame(layout: Layout) -> _BodyFrame:
    body = layout.body
    left, right = body.sides
    return _BodyFrame(
        root=body.root,
        neck=body.neck,
        left=left,
        right=right,
        feet=np.array(body.feet, dtype=np.int64).reshape(-1, 2),
        head=np.array(body.head, dtype=np.int64),
    )


@cache
def _side_pairs(
    layout: Layout, parts: _MirrorParts
) -> tuple[tuple[int, int] | None, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The shoulders (left, right), every other part's top joints, and the joints below them.

    Returns:
        the shoulder pair or None, ``(P, 2)`` left/right top joints and ``(P,)`` their parts,
        ``(Q, 2)`` left/right joints below a top joint in the same part and ``(Q,)`` theirs.

    """
    names = layout.joint_names
    empty = np.empty((0, 2), dtype=np.int64), np.empty(0, dtype=np.int64)
    if "ShoulderLeft" not in names or "ShoulderRight" not in names:
        return None, *empty, *empty
    reference = (names.index("ShoulderLeft"), names.index("ShoulderRight"))
    tops: list[tuple[int, int]] = []
    top_parts: list[int] = []
    below: list[tuple[int, int]] = []
    below_parts: list[int] = []
    for k in range(parts.count):
        if k == parts.part[reference[0]]:
            continue
        for joint in np.flatnonzero(parts.part == k):
            if "Left" not in names[joint]:
                continue
            parent = layout.parents[joint]
            top = parent < 0 or parts.part[parent] != k
            (tops if top else below).append((int(joint), int(parts.mirror[joint])))
            (top_parts if top else below_parts).append(k)
    return (
        reference,
        np.array(tops, dtype=np.int64).reshape(-1, 2),
        np.array(top_parts, dtype=np.int64),
        np.array(below, dtype=np.int64).reshape(-1, 2),
        np.array(below_parts, dtype=np.int64),
    )


@cache
def _side_arrays(
    layout: Layout, parts: _MirrorParts
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``_side_pairs`` as arrays for the kernels: ``(2,)`` shoulders (or empty), the pairs."""
    reference, pairs, part_ids, below, below_parts = _side_pairs(layout, parts)
    shoulders = np.array(reference if reference is not None else (), dtype=np.int64)
    return shoulders, pairs, part_ids, below, below_parts


@dataclass(frozen=True, eq=False)
class _LayoutInfo:
    """What the tracker derives from a layout, looked up once per frame."""

    layout: Layout
    parts: _MirrorParts
    weights: np.ndarray  # (J,) cost weights (_joint_weights)
    frame: _BodyFrame
    sides: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # _side_arrays

    @cached_property
    def parents(self) -> np.ndarray:
        """``(J,)`` each joint's parent, ``-1`` at the root."""
        return np.array(self.layout.parents, dtype=np.int64)

    @cached_property
    def usable(self) -> bool:
        """Whether the layout names the joints the facing check needs (``_BodyFrame.usable``)."""
        return bool(self.frame.usable)

    @cached_property
    def hit_layout(self) -> HitLayout:
        """What ``kernels.hit_frame`` needs of the layout: mirror parts, side pairs, body frame."""
        frame = self.frame
        body = FacingBody(
            frame.root, frame.neck, frame.left, frame.right, frame.pointers, self.parts.mirror
        )
        return HitLayout(self.parts.arrays, SideLayout(*self.sides), body)


@cache
def _joint_weights(layout: Layout, decay: float) -> np.ndarray:
    """``(J,)`` cost weight of each joint: ``decay ** depth`` in the layout's tree.

    The root and the joints next to it place a body reliably; hands, feet and head swing, get
    occluded and are the first a front/back flip throws a metre off, so they count less.
    """
    depth = np.zeros(layout.n_joints)
    for joint in range(layout.n_joints):
        parent = layout.parents[joint]
        while parent >= 0:
            depth[joint] += 1
            parent = layout.parents[parent]
    return decay**depth
