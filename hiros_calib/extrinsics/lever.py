"""How far the people's joints moved about where they stood: the lever a pair's rotation rests on.

The SDKs place each person's joints with offsets of their own, which the joint solve learns
per person and joint (:mod:`~hiros_calib.extrinsics.joint`). What is left to fix the rotation
between two cameras is how each joint *moved* about its own mean position: people walking
across the area move their joints by metres, a person exercising on one spot by a few tens of
centimetres. The body tracker's own errors change with the body's pose, so over so short a
lever they turn the pose by degrees, the same way in every span of time, and no split of the
recording shows it.
"""

from __future__ import annotations

import numpy as np

from hiros_calib.extrinsics.correspondences import Correspondences

__all__ = ["motion_lever"]


def motion_lever(correspondences: Correspondences | None) -> float | None:
    """RMS distance (m) of the joints from their own mean positions, in camera a's frame.

    Each (body pair, joint)'s positions are taken about their own weighted mean, so where a
    joint stands (the SDK's offset, to the solve) adds nothing; only its motion counts. A
    small rotation ``w`` moves an excursion ``d`` by ``w x d``: the typical lever of the
    rotation over its three axes is the RMS of ``|d|``. None when no joint pair has weight.
    """
    c = correspondences
    if c is None:
        return None
    valid = c.weights > 0
    if not valid.any():
        return None
    n_joints = c.weights.shape[1]
    cluster = (c.bodies[:, None] * n_joints + np.arange(n_joints)[None])[valid]
    points, weights = c.points_a[valid], c.weights[valid]
    _, index = np.unique(cluster, return_inverse=True)
    weight_sums = np.bincount(index, weights=weights)
    means = (
        np.stack([np.bincount(index, weights=weights * points[:, k]) for k in range(3)], axis=1)
        / weight_sums[:, None]
    )
    excursions = points - means[index]
    squared = np.einsum("n,ni,ni->", weights, excursions, excursions) / weights.sum()
    return float(np.sqrt(squared))
