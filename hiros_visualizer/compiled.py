"""Compiled (numba) filling of a drawn frame's MarkerArray, the general encoding's bytes.

``markers.encode_skeleton_markers`` fills a cached message template per frame shape: the
points of every sphere and line list, the label positions and the stamps. In numpy that is a
template copy, three scatters and a dozen small calls for the label heights (~60 us per frame
for four people); here it is one call, always (``hiros_core.compiled`` states the rule;
``markers`` imports this module at its first call).
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["draw", "visible_joints"]

_LABEL_LIFT = 0.25  # metres above the highest visible joint, as markers._label_tops


@njit(cache=True)
def draw(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    template: np.ndarray,
    rows: np.ndarray,
    column: int,
    visible: np.ndarray,
    points: np.ndarray,
    sources: np.ndarray,
    tops: np.ndarray,
    stamps: np.ndarray,
    sec: int,
    nanosec: int,
) -> np.ndarray:
    """A copy of ``template`` (8-byte words) with the frame's values (see ``markers._DrawPlan``).

    ``rows`` ``(P, J, W)`` hold the positions in columns ``column:column + 3`` (marker rows
    of a ``SkeletonRows`` stack, or stacked positions), ``visible`` ``(P, J)``; ``sources``
    index the positions as a flat ``(P, J, 3)`` array. Label ``p`` goes 25 cm above the
    first highest visible joint (``argmax``), or to the origin when none is visible.
    """
    out = template.copy()
    floats = out.view(np.float64)
    n_people, n_joints = visible.shape
    for i in range(points.size):
        joint, k = divmod(sources[i], 3)
        person, joint = divmod(joint, n_joints)
        floats[points[i]] = rows[person, joint, column + k]
    for p in range(n_people):
        best, top = -np.inf, -1
        for j in range(n_joints):
            if visible[p, j] and rows[p, j, column + 2] > best:
                best, top = rows[p, j, column + 2], j
        for k in range(3):
            value = 0.0  # adding 0.0 to x and y, as numpy does, turns -0.0 into 0.0
            if top >= 0:
                value = rows[p, top, column + k] + (_LABEL_LIFT if k == 2 else 0.0)
            floats[tops[3 * p + k]] = value
    words = out.view(np.int32)
    for i in range(stamps.size):
        words[stamps[i]] = sec
        words[stamps[i] + 1] = nanosec
    return out


@njit(cache=True)
def visible_joints(rows: np.ndarray, column: int, present: np.ndarray) -> np.ndarray:
    """``(P, J)`` present joints with three finite coordinates in ``rows[..., column:column+3]``.

    ``present & np.isfinite(positions).all(axis=2)`` in one call instead of four numpy calls
    (~7 us for four people, on every drawn frame).
    """
    n_people, n_joints = present.shape
    visible = np.zeros((n_people, n_joints), dtype=np.bool_)
    for p in range(n_people):
        for j in range(n_joints):
            visible[p, j] = (
                present[p, j]
                and np.isfinite(rows[p, j, column])
                and np.isfinite(rows[p, j, column + 1])
                and np.isfinite(rows[p, j, column + 2])
            )
    return visible
