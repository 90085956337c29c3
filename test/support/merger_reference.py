"""The merger's fusion stated in numpy: the readable specification of ``hiros_merger.kernels.fuse``.

Whole-array formulas written from the maths in ``hiros_merger/merger.py``'s docstring and the
kernels' docstrings (``weights.py``, ``robust.py``), not from the kernels'
loops; ``test/hiros_merger/test_kernel_reference.py`` holds the kernel equal to it on random
frames. Shapes: ``M`` tracks, ``C`` detections per track (padded), ``J`` joints.
"""

from __future__ import annotations

import numpy as np

from hiros_merger.kernel_args import (
    BodyLayout,
    FuseSettings,
    Fusion,
    RobustSettings,
    TrackDetections,
    WeightSettings,
)

__all__ = ["occluded", "reference_fuse"]


def _unit(vectors: np.ndarray) -> np.ndarray:
    """``vectors / |vectors|`` along the last axis (NaN for zero vectors)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return vectors / np.linalg.norm(vectors, axis=-1, keepdims=True)


def _mean_or_nan(total: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """``total / norm`` where ``norm`` is not 0, NaN there."""
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(norm != 0, total / norm, np.nan)


def detections_at(
    detections: TrackDetections, settings: WeightSettings, n_joints: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(M, C, J, 3)`` positions at the output time and velocities, confidences, weights.

    ``p + v · clip(age, ±max_extrapolation)`` (non-finite ``v`` as 0); the weight is
    ``max(conf, floor)^power / (1 + (age / staleness_scale)²) × (1 + depth_gain · depth)^-2``
    (the last where the camera is known; 0 where the position is not finite).
    """
    table = detections.table
    valid = (table >= 0)[..., None] & detections.present[np.maximum(table, 0), :n_joints]
    rows = detections.rows[np.maximum(table, 0), :n_joints]
    positions = np.where(valid[..., None], rows[..., 1:4], np.nan)
    velocities = np.where(valid[..., None], rows[..., 8:11], np.nan)
    ages = detections.ages
    dt = np.clip(ages, -settings.max_extrapolation, settings.max_extrapolation)
    positions = positions + np.where(np.isfinite(velocities), velocities, 0.0) * dt[..., None, None]
    confidences = np.where(valid, rows[..., 0], np.nan)
    confidences = np.where(np.isfinite(confidences), confidences, 1.0)
    weight = np.maximum(confidences, settings.confidence_floor) ** settings.confidence_power
    weight = np.where(np.isfinite(positions).all(axis=-1), weight, 0.0)
    weight = weight / (1.0 + (ages / settings.staleness_scale) ** 2)[..., None]
    known = np.isfinite(detections.cameras).all(axis=-1)
    depth = np.linalg.norm(positions - detections.cameras[:, :, None], axis=-1)
    with np.errstate(invalid="ignore"):
        weight = np.where(
            known[..., None], weight * (1.0 + settings.depth_gain * depth) ** -2.0, weight
        )
    return positions, velocities, confidences, weight


def weighted_median(positions: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """``(M, J, 3)`` per coordinate the smallest value whose cumulative weight reaches half.

    Of the finite values of positive weight (NaN where there are none).
    """
    weights = np.where(np.isfinite(positions), weight[..., None], 0.0)
    weights = np.where(weights > 0, weights, 0.0)
    keys = np.where(weights > 0, positions, np.inf)
    order = np.argsort(keys, axis=1, kind="stable")
    keys = np.take_along_axis(keys, order, axis=1)
    cumulative = np.cumsum(np.take_along_axis(weights, order, axis=1), axis=1)
    total = cumulative[:, -1:]
    first = np.argmax(cumulative >= 0.5 * total, axis=1)
    median = np.take_along_axis(keys, first[:, None], axis=1)[:, 0]
    return np.where(total[:, 0] > 0, median, np.nan)


def facing(  # noqa: PLR0917 - the kernel's arguments
    fused: np.ndarray,
    positions: np.ndarray,
    velocities: np.ndarray,
    cameras: np.ndarray,
    body: BodyLayout,
    settings: WeightSettings,
    up: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flips undone: ``(M, C, J, 3)`` positions and velocities, and ``(M, C)`` weight factors.

    Up: ``up`` ``(3,)``, or where that is not finite each track's fused root -> neck. Front:
    ``side × up``, ``side`` the sum over a track's detections with all their side joints of
    the left hip and shoulder less the right ones. A detection whose forward pointers, taken
    across up and summed as unit vectors, point against the front is flipped: reflected
    through the plane through its root normal to the front (velocities alike) and weighed
    ``flipped_weight``. The view factor is ``1 / (1 + oblique_gain · |sin θ|)²``, θ between
    the front and the direction from the fused root to the camera (1 where unknown).
    """
    if np.isfinite(up).all():
        up = np.broadcast_to(up, (len(fused), 3))
    else:
        up = _unit(fused[:, body.neck] - fused[:, body.root])  # (M, 3)
    sides = (positions[:, :, body.left] - positions[:, :, body.right]).sum(axis=2)  # (M, C, 3)
    sides = np.where(np.isfinite(sides).all(axis=-1, keepdims=True), sides, 0.0)
    front = _unit(np.cross(sides.sum(axis=1), up))
    factor = np.ones(positions.shape[:2])
    if len(body.pointers):
        pointing = positions[:, :, body.pointers[:, 1]] - positions[:, :, body.pointers[:, 0]]
        along = np.einsum("mcpa,ma->mcp", pointing, up)
        across = _unit(pointing - along[..., None] * up[:, None, None])
        summed = _unit(np.where(np.isfinite(across), across, 0.0).sum(axis=2))
        with np.errstate(invalid="ignore"):
            backwards = np.einsum("mca,ma->mc", summed, front) < 0
        factor = np.where(backwards, settings.flipped_weight, factor)
        root = positions[:, :, body.root : body.root + 1]
        depth = np.einsum("mcja,ma->mcj", positions - root, front)
        speed = np.einsum("mcja,ma->mcj", velocities, front)
        turned = (
            backwards
            & np.isfinite(root[:, :, 0]).all(axis=-1)
            & np.isfinite(front).all(axis=-1)[:, None]
        )[..., None, None]
        normal = front[:, None, None]
        positions = np.where(turned, positions - 2 * depth[..., None] * normal, positions)
        velocities = np.where(turned, velocities - 2 * speed[..., None] * normal, velocities)
    towards = _unit(cameras - fused[:, None, body.root])  # (M, C, 3)
    cosine = np.einsum("mca,ma->mc", towards, front)
    sine = np.sqrt(np.maximum(1.0 - cosine**2, 0.0))
    view = np.where(np.isfinite(cosine), 1.0 / (1.0 + settings.oblique_gain * sine) ** 2, np.nan)
    known = np.isfinite(cameras).all(axis=-1)
    return positions, velocities, factor * np.where(known & np.isfinite(view), view, 1.0)


def occluded(  # noqa: PLR0917 - the kernel's arguments
    fused: np.ndarray,
    positions: np.ndarray,
    cameras: np.ndarray,
    torso: np.ndarray,
    weight: np.ndarray,
    radius: float,
    factor: float,
) -> np.ndarray:
    """``weight`` times ``factor`` where another track's torso point blocks the camera's ray.

    A point ``q`` blocks the ray from camera ``o`` to joint ``p`` when it lies within
    ``radius`` of the ray and between ``o`` and ``radius`` short of ``p``.
    """
    n_tracks = len(fused)
    rel = positions - cameras[:, :, None]  # (M, C, J, 3) joint - camera
    length = np.linalg.norm(rel, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = rel / length[..., None]
        q = fused[None, None, :, torso] - cameras[:, :, None, None]  # (M, C, M', T, 3)
        along = np.einsum("mcja,mcota->mcjot", unit, q)
        across_sq = (q * q).sum(-1)[:, :, None] - along**2
        blocked = (across_sq < radius**2) & (along > 0) & (along < length[..., None, None] - radius)
    blocked[np.arange(n_tracks), :, :, np.arange(n_tracks)] = False  # not by its own torso
    return np.where(blocked.any(axis=(-2, -1)), weight * factor, weight)


def judged_residuals(
    positions: np.ndarray, fused: np.ndarray, groups: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(M, C, J)`` distances to ``fused``, and their limb mean and limb maximum.

    Over the joints of the limb whose positions and distances are finite; a joint that is
    not finite keeps its own distance.
    """
    residual = np.linalg.norm(positions - fused[:, None], axis=-1)
    finite = np.isfinite(positions).all(axis=-1)
    used = finite & np.isfinite(residual)
    in_limb = groups[:, None] == np.arange(groups.max() + 1)  # (J, G)
    masked = np.where(used, residual, 0.0)
    counts = np.einsum("mcj,jg->mcg", used.astype(float), in_limb.astype(float))
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.einsum("mcj,jg->mcg", masked, in_limb.astype(float)) / counts
    peaks = np.where(in_limb, masked[..., None], 0.0).max(axis=2)
    keep = finite & (counts[..., groups] > 0)
    return (
        residual,
        np.where(keep, means[..., groups], residual),
        np.where(keep, peaks[..., groups], residual),
    )


def cauchy_weights(
    weight: np.ndarray, residual: np.ndarray, own: np.ndarray, settings: RobustSettings
) -> np.ndarray:
    """``weight / (1 + (r / outlier_scale)²)``, 0 beyond the cutoffs where some camera is within."""
    with np.errstate(invalid="ignore"):
        robust = np.where(
            np.isfinite(residual), weight / (1.0 + (residual / settings.outlier_scale) ** 2), 0.0
        )
        inside = (residual <= settings.outlier_cutoff) & (own <= settings.limb_cutoff)
    any_inside = np.where(inside, robust, 0.0).sum(axis=1, keepdims=True) > 0
    return np.where(any_inside & ~inside, 0.0, robust)


def weighted_mean(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``(M, J, 3)`` the ``weights`` ``(M, C, J)`` mean over C of the finite ``values`` rows."""
    finite = np.isfinite(values).all(axis=-1)
    weights = np.where(finite, weights, 0.0)
    total = np.where(finite[..., None], values * weights[..., None], 0.0).sum(axis=1)
    return _mean_or_nan(total, weights.sum(axis=1)[..., None])


def reference_fuse(
    detections: TrackDetections, settings: FuseSettings, body: BodyLayout, up: np.ndarray
) -> Fusion:
    """``kernels.fuse`` in numpy: weights, median, facing and occlusion, robust mean, means."""
    weighting, robust = settings.weights, settings.robust
    positions, velocities, confidences, weight = detections_at(
        detections, weighting, len(body.groups)
    )
    fused = weighted_median(positions, weight)
    if body.has_front:
        positions, velocities, factors = facing(
            fused, positions, velocities, detections.cameras, body, weighting, up
        )
        weight = weight * factors[..., None]
    known = np.isfinite(detections.cameras).all(axis=-1)
    if weighting.occlusion_radius > 0 and len(fused) > 1 and known.any():
        weight = occluded(
            fused,
            positions,
            detections.cameras,
            body.torso,
            weight,
            weighting.occlusion_radius,
            weighting.occlusion_weight,
        )
    for _ in range(robust.iterations):
        _, limb, peak = judged_residuals(positions, fused, body.groups)
        fused = weighted_mean(positions, cauchy_weights(weight, limb, peak, robust))
    _, limb, peak = judged_residuals(positions, fused, body.groups)
    final = cauchy_weights(weight, limb, peak, robust)
    positive = np.where(final > 0, final, 0.0)
    confidence = _mean_or_nan((confidences * positive).sum(axis=1), positive.sum(axis=1))
    velocity = weighted_mean(velocities, final)
    return Fusion(fused, final, confidence, velocity)
