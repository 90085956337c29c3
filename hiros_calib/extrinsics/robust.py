"""The robust least squares over camera poses that every refinement runs, and its medians.

Gauss-Newton with iteratively reweighted least squares on the robust loss (``soft_l1``,
``huber``, ``cauchy`` or ``linear``) of each 3D residual, analytic Jacobians.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.geometry import RigidTransform

__all__ = [
    "Terms",
    "flatten_pairs",
    "loss_weights",
    "median_rows",
    "robust_solve",
    "weighted_median_rows",
]


def weighted_median_rows(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Median of each row over entries with positive weight (inf for an empty row)."""
    out = median_rows(values, weights > 0)
    return np.where(np.isfinite(out), out, np.inf)


def median_rows(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Median of each row of ``(R, K)`` over its ``valid`` entries (NaN for an empty row).

    One sort of the whole table instead of ``np.nanmedian``, which is many times slower on
    short rows.
    """
    if values.size == 0:
        return np.full(len(values), np.nan)
    ordered = np.sort(np.where(valid, values, np.inf), axis=1)
    count = valid.sum(axis=1)
    rows = np.arange(len(values))
    low = ordered[rows, np.maximum(count - 1, 0) // 2]
    high = ordered[rows, np.maximum(count // 2, 0) - (count == 0)]
    with np.errstate(invalid="ignore"):
        return np.where(count > 0, 0.5 * (low + high), np.nan)


def flatten_pairs(
    points_a: np.ndarray, points_b: np.ndarray, weights: np.ndarray
) -> tuple[np.ndarray, ...]:
    """(points_a, points_b, weights, joint, frame) rows of the pairs with positive weight."""
    joint = np.broadcast_to(np.arange(weights.shape[1])[None], weights.shape)
    frame = np.broadcast_to(np.arange(weights.shape[0])[:, None], weights.shape)
    valid = weights > 0
    return points_a[valid], points_b[valid], weights[valid], joint[valid], frame[valid]


def loss_weights(z: np.ndarray, loss: str) -> np.ndarray:
    """IRLS weight ``rho'(z)`` of a residual with squared scaled norm ``z = |r|^2 / s^2``."""
    if loss == "soft_l1":
        return 1.0 / np.sqrt(1.0 + z)
    if loss == "huber":
        return np.where(z <= 1.0, 1.0, 1.0 / np.sqrt(np.maximum(z, 1.0)))
    if loss == "cauchy":
        return 1.0 / (1.0 + z)
    if loss == "linear":
        return np.ones_like(z)
    msg = f"unknown loss {loss!r}: use soft_l1, huber, cauchy or linear"
    raise ValueError(msg)


def _normal_block(w: np.ndarray, q: np.ndarray, other: np.ndarray) -> np.ndarray:
    """``sum w J^T J'`` for Jacobians ``J = [-[q]_x, I]``, ``J' = [-[q']_x, I]`` (6 x 6).

    Written with weighted moments of the points, so nothing of size ``N x 3 x 6`` is built.
    """
    moment = np.einsum("n,ni,nj->ij", w, other, q)  # sum w q' q^T
    block = np.empty((6, 6))
    block[:3, :3] = np.trace(moment) * np.eye(3) - moment
    block[:3, 3:] = _skew(np.einsum("n,ni->i", w, q))
    block[3:, :3] = -_skew(np.einsum("n,ni->i", w, other))
    block[3:, 3:] = w.sum() * np.eye(3)
    return block


def _skew(v: np.ndarray) -> np.ndarray:
    """The matrix ``[v]_x`` of the cross product with ``v``."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


@dataclass
class Terms:
    """One set of correspondences ``T_a p_a - T_b p_b - offset`` of the robust solve."""

    camera_a: str
    camera_b: str
    points_a: np.ndarray
    points_b: np.ndarray
    weights: np.ndarray
    offsets: np.ndarray  # (N, 3) world frame, 0 when not modelled


def robust_solve(
    poses: dict[str, RigidTransform],
    unknown: list[str],
    terms: list[Terms],
    *,
    loss: str,
    scale: float,
    iterations: int = 100,
    tolerance: float = 1e-8,
) -> dict[str, RigidTransform]:
    """Poses of the ``unknown`` cameras minimising ``sum w rho(|T_a p_a - T_b p_b - d|^2/s^2)``.

    Gauss-Newton with iteratively reweighted least squares: each step solves the weighted
    normal equations of the linearised residuals (analytic Jacobian, rotations perturbed on
    the left, ``R <- exp(w) R``), the weights being the loss's influence at the current
    residuals. The loss acts on each 3D residual's length, so the estimate does not depend
    on how the world axes are oriented. A few small dense ``6U x 6U`` solves replace a generic
    solver's finite-difference Jacobians of the whole residual vector.
    """
    poses = dict(poses)
    column = {camera: 6 * k for k, camera in enumerate(unknown)}
    size = 6 * len(unknown)
    if not size:
        return poses
    for _ in range(iterations):
        hessian = np.zeros((size, size))
        gradient = np.zeros(size)
        for t in terms:
            moved_a = poses[t.camera_a].rotation.apply(t.points_a)
            moved_b = poses[t.camera_b].rotation.apply(t.points_b)
            residual = (
                moved_a + poses[t.camera_a].translation
                - moved_b - poses[t.camera_b].translation - t.offsets
            )  # fmt: skip
            z = np.einsum("ni,ni->n", residual, residual) / scale**2
            w = t.weights * loss_weights(z, loss)
            # normal equations of the unknown cameras' (rotation, translation) perturbations
            moving = [
                (column[camera], moved, sign)
                for camera, moved, sign in ((t.camera_a, moved_a, 1.0), (t.camera_b, moved_b, -1.0))
                if camera in column
            ]
            for k, moved, sign in moving:
                gradient[k : k + 3] += sign * np.einsum("n,ni->i", w, np.cross(moved, residual))
                gradient[k + 3 : k + 6] += sign * np.einsum("n,ni->i", w, residual)
                for m, other, other_sign in moving:
                    hessian[k : k + 6, m : m + 6] += (
                        sign * other_sign * _normal_block(w, moved, other)
                    )
        step = -np.linalg.solve(hessian + 1e-12 * np.eye(size), gradient)
        for camera, k in column.items():
            pose = poses[camera]
            poses[camera] = RigidTransform(
                Rotation.from_rotvec(step[k : k + 3]) * pose.rotation,
                pose.translation + step[k + 3 : k + 6],
            )
        if np.abs(step).max() < tolerance:
            break
    return poses
