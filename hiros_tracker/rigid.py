"""Rigid moves of skeleton rows: a camera's detections brought into the world frame."""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = [
    "move_boxes",
    "move_frame",
    "move_rows",
    "moved_frame",
]


@njit(cache=True, error_model="numpy")
def move_frame(  # noqa: PLR0917
    markers: np.ndarray,
    links: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    quaternion: np.ndarray,
) -> None:
    """A frame's marker and link rows ``(D, N, 20)`` and boxes ``(D, 22)`` moved in place.

    One call for the whole frame (see ``move_rows`` and ``move_boxes``).
    """
    for d in range(len(markers)):
        move_rows(markers[d], rotation, translation, quaternion)
    for d in range(len(links)):
        move_rows(links[d], rotation, translation, quaternion)
    move_boxes(boxes, rotation, translation, quaternion)


@njit(cache=True, error_model="numpy")
def moved_frame(  # noqa: PLR0917
    markers: np.ndarray,
    present: np.ndarray,
    links: np.ndarray,
    link_present: np.ndarray,
    boxes: np.ndarray,
    rotation: np.ndarray,
    translation: np.ndarray,
    quaternion: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``move_frame`` on copies of a frame's ``SkeletonRows`` fields, in their order.

    The input stays as it is. One call copies all five (a numpy ``copy`` each cost about as
    much as the move itself).
    """
    out = (markers.copy(), present.copy(), links.copy(), link_present.copy(), boxes.copy())
    move_frame(out[0], out[2], out[4], rotation, translation, quaternion)
    return out


@njit(cache=True, error_model="numpy")
def move_rows(
    rows: np.ndarray, rotation: np.ndarray, translation: np.ndarray, quaternion: np.ndarray
) -> None:
    """Marker/link rows ``(N, 20)`` moved in place by a rigid transform.

    ``R p + t`` on the position, ``quaternion`` ``(4, 4)`` (the product ``q_R ⊗ q``) on the
    orientation normalised first, ``R`` on each twist and acceleration vector; a field with
    any NaN becomes (stays) all NaN, a zero quaternion becomes NaN.
    """
    vector = np.empty(4)
    for i in range(len(rows)):
        _rotate(rows, i, 1, rotation, translation)
        for start in (8, 11, 14, 17):
            _rotate(rows, i, start, rotation, _ZERO3)
        _turn_quaternion(rows, i, 4, quaternion, vector)


@njit(cache=True, error_model="numpy")
def move_boxes(
    boxes: np.ndarray, rotation: np.ndarray, translation: np.ndarray, quaternion: np.ndarray
) -> None:
    """Bounding boxes ``(N, 22)`` moved in place: centre position (0:3), orientation (3:7)."""
    vector = np.empty(4)
    for i in range(len(boxes)):
        _rotate(boxes, i, 0, rotation, translation)
        _turn_quaternion(boxes, i, 3, quaternion, vector)


_ZERO3 = np.zeros(3)


@njit(cache=True, error_model="numpy")
def _turn_quaternion(
    rows: np.ndarray, i: int, start: int, quaternion: np.ndarray, vector: np.ndarray
) -> None:
    """``rows[i, start:start + 4]`` normalised, then multiplied by ``quaternion`` (4, 4).

    ``vector`` (4,) is scratch space, so that the per-row loop allocates nothing.
    """
    norm = math.sqrt(
        rows[i, start] * rows[i, start]
        + rows[i, start + 1] * rows[i, start + 1]
        + rows[i, start + 2] * rows[i, start + 2]
        + rows[i, start + 3] * rows[i, start + 3]
    )
    for k in range(4):
        vector[k] = rows[i, start + k] / norm
    for k in range(4):
        rows[i, start + k] = (
            quaternion[k, 0] * vector[0]
            + quaternion[k, 1] * vector[1]
            + quaternion[k, 2] * vector[2]
            + quaternion[k, 3] * vector[3]
        )


@njit(cache=True, error_model="numpy")
def _rotate(
    rows: np.ndarray, i: int, start: int, rotation: np.ndarray, translation: np.ndarray
) -> None:
    """``rows[i, start:start + 3]`` replaced by ``R v + t``."""
    x, y, z = rows[i, start], rows[i, start + 1], rows[i, start + 2]
    for k in range(3):
        rows[i, start + k] = (
            rotation[k, 0] * x + rotation[k, 1] * y + rotation[k, 2] * z + translation[k]
        )
