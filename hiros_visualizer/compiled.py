"""Compiled (numba) filling of a drawn frame's MarkerArray, same bytes as the numpy form.

``markers.encode_skeleton_markers`` fills a cached message template per frame shape: the
points of every sphere and line list, the label positions and the stamps. In numpy that is a
template copy, three scatters and a dozen small calls for the label heights (~60 us per frame
for four people); here it is one call. Imported only when numba is loaded already (the
pipeline's stages load it), like ``hiros_core.compiled``.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["draw"]

_LABEL_LIFT = 0.25  # metres above the highest visible joint, as markers._label_tops


@njit(cache=True)
def draw(  # noqa: PLR0917 - a compiled kernel takes plain positional values
    template: np.ndarray,
    positions: np.ndarray,
    visible: np.ndarray,
    points: np.ndarray,
    sources: np.ndarray,
    tops: np.ndarray,
    stamps: np.ndarray,
    sec: int,
    nanosec: int,
) -> np.ndarray:
    """A copy of ``template`` (8-byte words) with the frame's values (see ``markers._DrawPlan``).

    ``positions`` ``(P, J, 3)``, ``visible`` ``(P, J)``; label ``p`` goes 25 cm above the
    first highest visible joint (``argmax``), or to the origin when none is visible.
    """
    out = template.copy()
    floats = out.view(np.float64)
    flat = positions.reshape(-1)
    for i in range(points.size):
        floats[points[i]] = flat[sources[i]]
    n_people, n_joints = visible.shape
    for p in range(n_people):
        best, top = -np.inf, -1
        for j in range(n_joints):
            if visible[p, j] and positions[p, j, 2] > best:
                best, top = positions[p, j, 2], j
        for k in range(3):
            value = 0.0  # adding 0.0 to x and y, as numpy does, turns -0.0 into 0.0
            if top >= 0:
                value = positions[p, top, k] + (_LABEL_LIFT if k == 2 else 0.0)
            floats[tops[3 * p + k]] = value
    words = out.view(np.int32)
    for i in range(stamps.size):
        words[stamps[i]] = sec
        words[stamps[i] + 1] = nanosec
    return out
