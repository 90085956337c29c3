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
    """RMS lever arm (m) of the joints' motion about their own means, about the weakest axis.

    Each (body pair, joint)'s camera-a positions are taken about their own weighted mean. A
    small rotation ``w`` moves an excursion ``d`` by ``w x d``, so the rotation's information
    is ``sum |d|^2 I - d d^T``, whose smallest eigenvalue is the scatter of ``d`` outside its
    main direction: the two smaller eigenvalues of the excursions' scatter. Its square root is
    returned; None when no joint pair has weight.
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
    scatter = np.einsum("n,ni,nj->ij", weights, excursions, excursions) / weights.sum()
    smaller_two = np.linalg.eigvalsh(scatter)[:2].sum()
    return float(np.sqrt(max(smaller_two, 0.0)))
